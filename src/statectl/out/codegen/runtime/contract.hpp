// statectl runtime: numbered contract checks (shared by every generated device).
//
// A failed check names its number and a one-line reason, calls the handler the
// application installed (if any) and stops the program: no exceptions, no heap.
// Numbers: 1xx device, 2xx subject/observers, 3xx queue.
#ifndef STATECTL_CONTRACT_HPP
#define STATECTL_CONTRACT_HPP

#include <cstdio>
#include <cstdlib>

// Branch hints for cold paths (C++17 has no [[unlikely]]); plain code elsewhere.
// STATECTL_UNREACHABLE marks a default the generator proved impossible (static_assert).
#if defined(__GNUC__) || defined(__clang__)
#define STATECTL_COLD __attribute__((cold, noinline))
#define STATECTL_UNLIKELY(x) __builtin_expect(!!(x), 0)
#define STATECTL_UNREACHABLE() __builtin_unreachable()
#elif defined(_MSC_VER)
#define STATECTL_COLD __declspec(noinline)
#define STATECTL_UNLIKELY(x) (x)
#define STATECTL_UNREACHABLE() __assume(0)
#else
#define STATECTL_COLD
#define STATECTL_UNLIKELY(x) (x)
#define STATECTL_UNREACHABLE() std::abort()
#endif

namespace statectl {

/// Called with the check's number and reason before the program aborts.
using ContractHandler = void (*)(int id, const char* reason) noexcept;

inline ContractHandler& contract_handler() noexcept {
  static ContractHandler handler = nullptr;
  return handler;
}

[[noreturn]] STATECTL_COLD inline void contract_failed(int id, const char* reason) noexcept {
  if (ContractHandler handler = contract_handler()) {
    handler(id, reason);
  }
  std::fprintf(stderr, "statectl contract %d failed: %s\n", id, reason);
  std::abort();
}

}  // namespace statectl

#define STATECTL_REQUIRE(id, cond, reason) \
  (STATECTL_UNLIKELY(!(cond)) ? ::statectl::contract_failed((id), (reason)) : static_cast<void>(0))

#endif  // STATECTL_CONTRACT_HPP
