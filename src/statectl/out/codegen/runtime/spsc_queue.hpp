// statectl runtime: a fixed-capacity, lock-free single-producer/single-consumer queue.
//
// One producer thread (a monitor) pushes, the device's owner pops; neither ever
// blocks or allocates. push() on a full queue returns false: the caller decides.
#ifndef STATECTL_SPSC_QUEUE_HPP
#define STATECTL_SPSC_QUEUE_HPP

#include <atomic>
#include <cstddef>
#include <type_traits>

namespace statectl {

template <typename T, std::size_t Capacity>
class SpscQueue {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0,
                "SpscQueue capacity must be a power of two");
  static_assert(std::is_trivially_copyable<T>::value, "SpscQueue holds plain values");

 public:
  static constexpr std::size_t kCapacity = Capacity;

  /// Producer side: false when full (nothing is overwritten).
  bool push(const T& value) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - head_.load(std::memory_order_acquire) == Capacity) {
      return false;
    }
    slots_[tail & (Capacity - 1)] = value;
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Consumer side: false when empty.
  bool pop(T& out) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head == tail_.load(std::memory_order_acquire)) {
      return false;
    }
    out = slots_[head & (Capacity - 1)];
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  std::size_t size() const noexcept {
    return tail_.load(std::memory_order_acquire) - head_.load(std::memory_order_acquire);
  }

 private:
  std::atomic<std::size_t> head_{0};
  std::atomic<std::size_t> tail_{0};
  T slots_[Capacity] = {};
};

}  // namespace statectl

#endif  // STATECTL_SPSC_QUEUE_HPP
