// statectl runtime: trace hooks that compile to nothing unless STATECTL_TRACE is 1.
//
// With tracing on, a device calls its Tracer for every record the Python runtime
// emits (event, exit, transition, enter, invoke, ignored, finished). With it off
// the calls and the tracer pointer do not exist in the object code.
#ifndef STATECTL_TRACE_HPP
#define STATECTL_TRACE_HPP

#ifndef STATECTL_TRACE
#define STATECTL_TRACE 0
#endif

namespace statectl {

class Tracer {
 public:
  virtual void started(const char* /*device*/) noexcept {}
  virtual void event(const char* /*device*/, const char* /*event*/) noexcept {}
  virtual void exited(const char* /*device*/, const char* /*state*/) noexcept {}
  /// `targets` is empty for a targetless transition; `label` is "event [guard]".
  virtual void taken(const char* /*device*/, const char* /*source*/, const char* /*targets*/,
                     const char* /*label*/) noexcept {}
  virtual void entered(const char* /*device*/, const char* /*state*/) noexcept {}
  virtual void invoked(const char* /*device*/, int /*number*/, const char* /*name*/,
                       const char* /*method*/) noexcept {}
  /// `reason`: "declared ignored", "guard false" or "no transition".
  virtual void ignored(const char* /*device*/, const char* /*event*/,
                       const char* /*reason*/) noexcept {}
  virtual void finished(const char* /*device*/) noexcept {}

 protected:
  Tracer() = default;
  Tracer(const Tracer&) = default;
  Tracer& operator=(const Tracer&) = default;
  ~Tracer() = default;
};

}  // namespace statectl

#if STATECTL_TRACE
#define STATECTL_TRACE_CALL(tracer, call) \
  do {                                     \
    if ((tracer) != nullptr) {             \
      (tracer)->call;                      \
    }                                      \
  } while (false)
#else
#define STATECTL_TRACE_CALL(tracer, call) \
  do {                                     \
  } while (false)
#endif

#endif  // STATECTL_TRACE_HPP
