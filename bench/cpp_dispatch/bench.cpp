// Dispatch benchmark: the generated Motor against a hand-written enum/switch Motor,
// in one binary and one run. Both derive from the same statectl::Subject and notify
// the same observer, so the difference is the dispatch itself.
//
// A single dispatch is far shorter than a clock read, so each sample times a batch of
// kBatch dispatches and divides; p50/p99/max are over the samples of all repeats,
// after warm-up. The implementations alternate per batch, and which goes first
// alternates too, so that drift and cache state hit both alike.
//
// Both read the events through a pointer the compiler cannot see through, so neither
// dispatch is specialised for a known event. `bench --count N` instead runs N dispatches
// of each in run_generated / run_handwritten (never inlined) and exits: run.py counts
// their instructions with `valgrind --tool=callgrind --toggle-collect=...`.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "motor.hpp"

namespace {

using motor::Event;
using motor::Invoke;

// -- the hand-written reference: one switch over the state, then the event ------------------

namespace hand {

enum class State : std::uint8_t { Blocked, Moving, Returning };

class Motor : public statectl::Subject<Invoke, 3> {
 public:
  void dispatch(Event e) noexcept {
    switch (state_) {
      case State::Blocked:
        if (e == Event::Movement) {
          go(State::Moving);
          notify(Invoke::Moving);
        } else if (e == Event::Initialization && previous_ == State::Moving) {
          go(State::Returning);
          notify(Invoke::Returning);
        }
        break;
      case State::Moving:
        if (e == Event::MovementCompletion) {
          go(State::Blocked);
        } else if (e == Event::Error) {
          go(State::Returning);
          notify(Invoke::Error);
        }
        break;
      case State::Returning:
        if (e == Event::InitializationCompletion || e == Event::ErrorCompletion) {
          go(State::Blocked);
        }
        break;
    }
  }
  State state() const noexcept { return state_; }

 private:
  void go(State next) noexcept {
    previous_ = state_;
    state_ = next;
  }
  State state_ = State::Blocked;
  State previous_ = State::Blocked;  // "no previous" never equals Moving
};

}  // namespace hand

class Counter final : public statectl::Observer<Invoke> {
 public:
  void update(Invoke invoke) noexcept override { calls += 1 + static_cast<unsigned>(invoke); }
  std::uint64_t calls = 0;
};

// Every transition of the chart once, plus an ignored and a guard-false event.
constexpr Event kCycle[] = {
    Event::Movement,       Event::MovementCompletion, Event::Initialization,
    Event::InitializationCompletion, Event::Movement, Event::Error,
    Event::ErrorCompletion, Event::Error /* ignored */, Event::Initialization /* guard false */,
    Event::Movement,       Event::MovementCompletion, Event::Movement,
    Event::MovementCompletion, Event::Initialization, Event::InitializationCompletion,
    Event::Movement,
};
constexpr std::size_t kCycleLength = sizeof kCycle / sizeof kCycle[0];
static_assert((kCycleLength & (kCycleLength - 1)) == 0, "the cycle length is a power of two");
constexpr int kBatch = 1024;
constexpr int kWarmup = 200;
constexpr int kSamples = 2000;
constexpr int kRepeats = 5;

// volatile: the compiler must load the pointer, so it cannot know which events come.
const Event* volatile g_events = kCycle;

template <typename Device>
inline void drive(Device& device, const Event* events, int n) {
  for (int i = 0; i < n; ++i) {
    device.dispatch(events[static_cast<std::size_t>(i) & (kCycleLength - 1)]);
  }
}

template <typename Device>
double batch(Device& device) {
  const Event* events = g_events;
  const auto t0 = std::chrono::steady_clock::now();
  drive(device, events, kBatch);
  const auto t1 = std::chrono::steady_clock::now();
  return std::chrono::duration<double, std::nano>(t1 - t0).count() / kBatch;
}

// The instruction-count entry points: the same loop as batch(), no clock.
#if defined(__GNUC__) || defined(__clang__)
#define BENCH_NOINLINE __attribute__((noinline))
#else
#define BENCH_NOINLINE
#endif

BENCH_NOINLINE void run_generated(motor::Motor& device, int n) { drive(device, g_events, n); }
BENCH_NOINLINE void run_handwritten(hand::Motor& device, int n) { drive(device, g_events, n); }

double percentile(std::vector<double>& v, double p) {
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5);
  return v[i];
}

void report(const char* name, std::vector<double>& v) {
  const double p50 = percentile(v, 0.50);
  const double p99 = percentile(v, 0.99);
  std::printf("%s p50=%.3f p99=%.3f max=%.3f samples=%zu\n", name, p50, p99, v.back(),
              v.size());
}

}  // namespace

int main(int argc, char** argv) {
  motor::Motor generated;
  hand::Motor handwritten;
  Counter a;
  Counter b;
  for (int i = 0; i < 3; ++i) {
    generated.attach(a, static_cast<Invoke>(i));
    handwritten.attach(b, static_cast<Invoke>(i));
  }
  generated.start();
  if (argc == 3 && std::strcmp(argv[1], "--count") == 0) {
    const int n = std::atoi(argv[2]);
    run_generated(generated, n);
    run_handwritten(handwritten, n);
    std::printf("count %d %s\n", n, a.calls == b.calls ? "same" : "MISMATCH");
    return a.calls == b.calls ? 0 : 1;
  }
  std::vector<double> gen_ns;
  std::vector<double> hand_ns;
  gen_ns.reserve(kSamples * kRepeats);
  hand_ns.reserve(kSamples * kRepeats);
  for (int r = 0; r < kRepeats; ++r) {
    for (int i = 0; i < kWarmup; ++i) {
      batch(generated);
      batch(handwritten);
    }
    for (int i = 0; i < kSamples; ++i) {
      if (i % 2 == 0) {
        gen_ns.push_back(batch(generated));
        hand_ns.push_back(batch(handwritten));
      } else {
        hand_ns.push_back(batch(handwritten));
        gen_ns.push_back(batch(generated));
      }
    }
  }
  // both ran the same events: they must have notified the same invokes
  if (a.calls != b.calls) {
    std::printf("MISMATCH generated %llu vs hand-written %llu notifications\n",
                static_cast<unsigned long long>(a.calls),
                static_cast<unsigned long long>(b.calls));
    return 1;
  }
  report("generated", gen_ns);
  report("handwritten", hand_ns);
  std::printf("sizeof generated=%zu handwritten=%zu\n", sizeof generated, sizeof handwritten);
  return 0;
}
