// The Motor case study in C++: the generated device (generated/motor.hpp) drives a
// simulated motor on a simulated clock and prints the same trace as `statectl demo`.
//
// Hand-written application code around the generated device:
//   SimClock  - deterministic time and a fixed set of timers (no heap);
//   SimMotor  - the motor's API (the generated MotorApi observer): moves at 10 units/s
//               and reports a completion event when it arrives;
//   Monitor   - the paper's monitoring of Moving (the device's entry/exit hooks), polling
//               every 0.1 s;
//   Printer   - the statectl::Tracer that prints `t=  0.00  Motor  kind  text` lines.
// Events carry data here (amount, position, detail), so the application keeps its own
// small queue of (event, data) and is the device's owner; post() is for monitor threads.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "motor.hpp"

namespace {

constexpr double kTick = 0.05;
constexpr double kPeriod = 0.1;
constexpr double kSpeed = 10.0;
constexpr const char* kFault = "motor stalled";

double now = 0.0;  // the simulated clock

// -- event data, formatted like Python's format_data ------------------------------------------

struct Data {
  const char* key = nullptr;  // nullptr: no data
  double number = 0.0;
  const char* text = nullptr;
  bool integral = false;  // an int in the Python demo (amount), else a float (position)
};

// As the Python trace prints numbers: an int as it is, a float as its shortest exact
// text with ".0" when that has no point or exponent (10.0, 2.5, 1e-07).
void print_number(double v, bool integral) {
  if (integral) {
    std::printf("%.0f", v);
    return;
  }
  char text[32];
  auto end = std::to_chars(text, text + sizeof text - 1, v).ptr;
  *end = '\0';
  std::printf("%s%s", text, std::strpbrk(text, ".ein") != nullptr ? "" : ".0");
}

// -- the trace -------------------------------------------------------------------------------

void stamp_at(double t, const char* kind) { std::printf("t=%7.2f  Motor  %-8s ", t, kind); }
void stamp(const char* kind) { stamp_at(now, kind); }

// A monitor starting or stopping is printed after its microstep's exit, transition and
// entry lines, as statectl's trace has it (the record of a microstep comes first, then
// what its hooks did): the hooks note the line, the printer writes it at the next line
// that is not part of the microstep.
struct Note {
  double time;
  const char* text;
};
Note notes[4];
int noted = 0;

void note(const char* text) {
  if (noted < 4) notes[noted++] = Note{now, text};
}

void print_notes() {
  for (int i = 0; i < noted; ++i) {
    stamp_at(notes[i].time, "monitor");
    std::puts(notes[i].text);
  }
  noted = 0;
}

Data current;  // the data of the event being dispatched

class Printer final : public statectl::Tracer {
 public:
  void started(const char*) noexcept override {
    print_notes();
    stamp("run");
    std::puts("started");
  }
  void event(const char*, const char* e) noexcept override {
    print_notes();
    stamp("event");
    std::printf("%s", e);
    if (current.key != nullptr) {
      std::printf(" {%s: ", current.key);
      if (current.text != nullptr) {
        std::printf("%s", current.text);
      } else {
        print_number(current.number, current.integral);
      }
      std::printf("}");
    }
    std::printf("\n");
  }
  void exited(const char*, const char* s) noexcept override {
    stamp("exit");
    std::puts(s);
  }
  void taken(const char*, const char* s, const char* t, const char* l) noexcept override {
    stamp("state");
    std::printf("%s -> %s  on %s\n", s, *t != '\0' ? t : "(targetless)", l);
  }
  void entered(const char*, const char* s) noexcept override {
    stamp("enter");
    std::puts(s);
  }
  void invoked(const char*, int n, const char* name, const char* method) noexcept override {
    print_notes();
    stamp("invoke");
    std::printf("#%d %s -> observer %s()\n", n, name, method);
    ++invokes;
  }
  void ignored(const char*, const char* e, const char* r) noexcept override {
    print_notes();
    stamp("ignored");
    std::printf("%s (%s)\n", e, r);
  }
  void finished(const char*) noexcept override {
    print_notes();
    stamp("run");
    std::puts("finished");
  }
  int invokes = 0;
};

// -- a fixed set of timers -------------------------------------------------------------------

enum class Timer { Arrival, Poll, Count };

struct SimClock {
  double when[static_cast<int>(Timer::Count)] = {};
  bool armed[static_cast<int>(Timer::Count)] = {};
  void call_later(Timer t, double delay) {
    when[static_cast<int>(t)] = now + delay;
    armed[static_cast<int>(t)] = true;
  }
  void cancel(Timer t) { armed[static_cast<int>(t)] = false; }
  bool next(double limit, Timer& out) const {  // earliest armed timer due by limit
    bool found = false;
    for (int i = 0; i < static_cast<int>(Timer::Count); ++i) {
      if (armed[i] && when[i] <= limit && (!found || when[i] < when[static_cast<int>(out)])) {
        out = static_cast<Timer>(i);
        found = true;
      }
    }
    return found;
  }
};

SimClock clock_;

// -- the application's event queue: (event, data), fixed capacity -----------------------------

struct Item {
  motor::Event event;
  Data data;
};

Item items[8];
int head = 0;
int count = 0;

void post(motor::Event e, Data d) {
  items[(head + count) % 8] = Item{e, d};
  ++count;
}

// -- the simulated motor: the generated observer ----------------------------------------------

class SimMotor final : public motor::MotorApi {
 public:
  void Movement() noexcept override {
    method_ = motor::Event::MovementCompletion;
    move_to(position() + current.number);
  }
  void Initialization() noexcept override {
    method_ = motor::Event::InitializationCompletion;
    return_to(previous_);
  }
  void Error() noexcept override {
    method_ = motor::Event::ErrorCompletion;
    return_to(previous_);
  }

  double position() const {
    if (!moving_) {
      return position_;
    }
    const double travelled = (now - start_time_) * kSpeed;
    const double distance = target_ - start_;
    if (travelled >= std::fabs(distance)) {
      return target_;
    }
    return start_ + (distance > 0 ? travelled : -travelled);
  }

  void arrive() {
    position_ = target_;
    moving_ = false;
    post(method_, Data{"position", position_, nullptr});
  }

  int calls = 0;
  double fault_due = -1.0;  // a fault is armed from this time on

 private:
  void log(const char* method, const char* call, bool with_arg, double arg) {
    stamp("api");
    std::printf("%s() -> SimMotor.%s(", method, call);
    if (with_arg) {
      std::printf("%.1f", arg);
    }
    std::printf(")\n");
    ++calls;
  }
  const char* method_name() const {
    switch (method_) {
      case motor::Event::MovementCompletion:
        return "Movement";
      case motor::Event::InitializationCompletion:
        return "Initialization";
      default:
        return "Error";
    }
  }
  void move_to(double target) {
    if (moving_) {
      stop();
    }
    log(method_name(), "move_to", true, target);
    previous_ = position();
    travel(target);
  }
  void return_to(double where) {
    if (moving_) {
      stop();
    }
    log(method_name(), "return_to", true, where);
    travel(where);
  }
  void stop() {
    log(method_name(), "stop", false, 0.0);
    position_ = position();
    clock_.cancel(Timer::Arrival);
    moving_ = false;
  }
  void travel(double target) {
    start_ = position_;
    target_ = target;
    start_time_ = now;
    moving_ = true;
    clock_.call_later(Timer::Arrival, std::fabs(target - start_) / kSpeed);
  }

  motor::Event method_ = motor::Event::MovementCompletion;
  double position_ = 0.0;
  double previous_ = 0.0;
  double start_ = 0.0;
  double target_ = 0.0;
  double start_time_ = 0.0;
  bool moving_ = false;
};

SimMotor sim;

// -- the monitor of Moving: started and stopped by the device's entry/exit hooks ---------------

struct Monitor {
  void on_entry(motor::State s) noexcept {
    if (s == motor::State::Moving) {
      note("Moving started");
      clock_.call_later(Timer::Poll, kPeriod);
    }
  }
  void on_exit(motor::State s) noexcept {
    if (s == motor::State::Moving) {
      note("Moving stopped");
      clock_.cancel(Timer::Poll);
    }
  }
  static void poll() {
    print_notes();
    if (sim.fault_due >= 0.0 && now >= sim.fault_due) {
      sim.fault_due = -1.0;
      stamp("fault");
      std::printf("'%s' while Moving -> raises Error\n", kFault);
      post(motor::Event::Error, Data{"detail", 0.0, kFault});
    }
    clock_.call_later(Timer::Poll, kPeriod);
  }
};

motor::BasicMotor<Monitor> device;  // the generated device with the monitor as its hooks
Printer printer;
int processed = 0;

void run_until_idle() {
  while (count > 0) {
    const Item item = items[head];
    head = (head + 1) % 8;
    --count;
    current = item.data;
    ++processed;
    device.dispatch(item.event);
  }
}

/// Advance simulated time until the device rests in `state` (statectl demo's _until).
void until(motor::State state) {
  run_until_idle();
  for (int guard = 0; guard < 10000 && !(device.in(state) && count == 0); ++guard) {
    Timer t = Timer::Arrival;
    double step = kTick;  // as statectl demo: up to the next timer, at most one tick
    if (clock_.next(1e300, t)) {
      const double due = clock_.when[static_cast<int>(t)] - now;
      step = due < 0.0 ? 0.0 : (due < kTick ? due : kTick);
    }
    const double limit = now + step;
    while (clock_.next(limit, t)) {
      now = clock_.when[static_cast<int>(t)];
      clock_.armed[static_cast<int>(t)] = false;
      if (t == Timer::Arrival) {
        sim.arrive();
      } else {
        Monitor::poll();
      }
      run_until_idle();
    }
    now = limit;
    run_until_idle();
  }
}

}  // namespace

int main() {
  std::printf("statectl demo: Motor on SimMotor (driver sim-motor)\n");
  std::printf("invokes: ");
  for (std::size_t i = 0; i < motor::kInvokeCount; ++i) {
    std::printf("%s#%zu %s -> %s()", i == 0 ? "" : ", ", i, motor::detail::kInvokes[i].name,
                motor::detail::kInvokes[i].method);
  }
  std::printf("\n\n");
  device.set_tracer(&printer);
  device.attach(sim, motor::Invoke::Moving);
  device.attach(sim, motor::Invoke::Returning);
  device.attach(sim, motor::Invoke::Error);
  current = Data{};
  device.start();

  post(motor::Event::Movement, Data{"amount", 10, nullptr, true});
  until(motor::State::Blocked);
  post(motor::Event::Initialization, Data{});
  until(motor::State::Blocked);
  post(motor::Event::Movement, Data{"amount", 10, nullptr, true});
  sim.fault_due = now + 0.45;
  until(motor::State::Blocked);
  printer.finished("Motor");

  print_notes();
  std::printf("\nfinal state ");
  const char* sep = "";
  for (std::size_t s = 0; s < motor::kStateCount; ++s) {
    if (device.in(static_cast<motor::State>(s))) {
      std::printf("%s%s", sep, motor::detail::kStateNames[s]);
      sep = ", ";
    }
  }
  std::printf("; %d events processed; %d invokes issued; %d API calls\n", processed,
              printer.invokes, sim.calls);
  return device.in(motor::State::Blocked) ? 0 : 1;
}
