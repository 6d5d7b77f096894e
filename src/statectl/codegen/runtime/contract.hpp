// statectl runtime: numbered contract checks (shared by every generated device).
//
// A failed check names its number and a one-line reason, calls the handler the
// application installed (if any) and stops the program: no exceptions, no heap.
// Numbers: 1xx device, 2xx subject/observers, 3xx queue.
#ifndef STATECTL_CONTRACT_HPP
#define STATECTL_CONTRACT_HPP

#include <cstdio>
#include <cstdlib>

namespace statectl {

/// Called with the check's number and reason before the program aborts.
using ContractHandler = void (*)(int id, const char* reason) noexcept;

inline ContractHandler& contract_handler() noexcept {
  static ContractHandler handler = nullptr;
  return handler;
}

[[noreturn]] inline void contract_failed(int id, const char* reason) noexcept {
  if (ContractHandler handler = contract_handler()) {
    handler(id, reason);
  }
  std::fprintf(stderr, "statectl contract %d failed: %s\n", id, reason);
  std::abort();
}

}  // namespace statectl

#define STATECTL_REQUIRE(id, cond, reason) \
  ((cond) ? static_cast<void>(0) : ::statectl::contract_failed((id), (reason)))

#endif  // STATECTL_CONTRACT_HPP
