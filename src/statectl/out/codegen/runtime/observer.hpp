// statectl runtime: the paper's modified observer pattern.
//
// An Observer is a device with its API; update(invoke) maps an invoke number to
// one API call. Unlike the textbook pattern the Subject notifies only the one
// observer registered for a notification's invoke number, never all of them.
#ifndef STATECTL_OBSERVER_HPP
#define STATECTL_OBSERVER_HPP

#include <array>
#include <cstddef>

#include "statectl/contract.hpp"

namespace statectl {

template <typename Invoke>
class Observer {
 public:
  virtual void update(Invoke invoke) noexcept = 0;

 protected:
  Observer() = default;
  Observer(const Observer&) = default;
  Observer& operator=(const Observer&) = default;
  ~Observer() = default;  // never deleted through this base
};

/// Routes each invoke number to at most one observer; N is the number of invokes.
template <typename Invoke, std::size_t N>
class Subject {
 public:
  static constexpr std::size_t kInvokes = N;

  /// Register `observer` for `invoke` (201: out of range, 202: claimed by another).
  void attach(Observer<Invoke>& observer, Invoke invoke) noexcept {
    const auto n = static_cast<std::size_t>(invoke);
    STATECTL_REQUIRE(201, n < N, "attach: invoke number out of range");
    STATECTL_REQUIRE(202, routes_[n] == nullptr || routes_[n] == &observer,
                     "attach: invoke number has an observer already; detach it first");
    routes_[n] = &observer;
  }

  void detach(Invoke invoke) noexcept {
    const auto n = static_cast<std::size_t>(invoke);
    STATECTL_REQUIRE(203, n < N, "detach: invoke number out of range");
    routes_[n] = nullptr;
  }

  Observer<Invoke>* observer_for(Invoke invoke) const noexcept {
    const auto n = static_cast<std::size_t>(invoke);
    return n < N ? routes_[n] : nullptr;
  }

 protected:
  /// Notify the one observer registered for `invoke`, if any.
  void notify(Invoke invoke) noexcept {
    Observer<Invoke>* observer = routes_[static_cast<std::size_t>(invoke)];
    if (observer != nullptr) {
      observer->update(invoke);
    }
  }

 private:
  std::array<Observer<Invoke>*, N> routes_{};
};

}  // namespace statectl

#endif  // STATECTL_OBSERVER_HPP
