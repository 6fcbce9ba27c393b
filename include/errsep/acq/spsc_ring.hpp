#pragma once
// A fixed-capacity, lock-free ring for exactly one producer thread and one consumer thread.
//
// Why our own and not Boost.Lockfree: the sampler needs three things a plain queue does not give
// in one place: a count of what could not be pushed (overruns must be reported, never silent),
// capacity fixed at construction (no allocation afterwards), and trivially copyable items only
// (so a push is a memcpy and never throws).  The design follows the usual SPSC principles
// (rigtorp/SPSCQueue, LinuxCNC's sampler): monotonically increasing 64-bit write and read counts,
// each on its own cache line, published with release and observed with acquire; each side keeps a
// cached copy of the other side's count so that, in the common case, a push or pop touches only
// its own cache line.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace errsep::acq {

/// Size used to keep the producer's and the consumer's data on separate cache lines.  A constant
/// rather than std::hardware_destructive_interference_size, whose value GCC warns may change
/// between compiler versions (it would change the layout, and this header is public).
inline constexpr std::size_t kCacheLineBytes = 64;

template <class T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>,
                "SpscRing carries trivially copyable items only (push must not throw)");

 public:
  /// Allocates room for `capacity` items, rounded up to a power of two (at least 2).  Throws
  /// std::invalid_argument for capacity 0 or > 2^40.  Not real-time safe (allocates).
  explicit SpscRing(std::size_t capacity)
      : capacity_(round_up_pow2(capacity)), mask_(capacity_ - 1) {
    slots_ = std::make_unique<T[]>(capacity_);
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  /// Number of items the ring holds when full.
  std::size_t capacity() const noexcept { return capacity_; }

  /// Producer side.  Copies `item` in and returns true, or returns false (and counts one
  /// rejected push) when the ring is full.  Real-time safe: no allocation, no lock, no system
  /// call, no exception, bounded time.  Call from the single producer thread only.
  bool try_push(const T& item) noexcept {
    const std::uint64_t w = write_.load(std::memory_order_relaxed);
    if (w - prod_cached_read_ >= capacity_) {
      // Looks full with the stale copy: refresh it (acquire pairs with the consumer's release,
      // so the consumer has finished reading the slot we are about to overwrite).
      prod_cached_read_ = read_.load(std::memory_order_acquire);
      if (w - prod_cached_read_ >= capacity_) {
        // Single writer: a load/store pair is enough and cheaper than a read-modify-write.
        rejected_.store(rejected_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
        return false;
      }
    }
    slots_[w & mask_] = item;
    write_.store(w + 1, std::memory_order_release);  // publishes the slot to the consumer
    return true;
  }

  /// Consumer side.  Moves the oldest item into `out` and returns true, or returns false when
  /// the ring is empty.  Real-time safe (same guarantees as try_push).  Consumer thread only.
  bool try_pop(T& out) noexcept {
    const std::uint64_t r = read_.load(std::memory_order_relaxed);
    if (r == cons_cached_write_) {
      cons_cached_write_ = write_.load(std::memory_order_acquire);  // pairs with push's release
      if (r == cons_cached_write_) return false;
    }
    out = slots_[r & mask_];
    read_.store(r + 1, std::memory_order_release);  // frees the slot for the producer
    return true;
  }

  /// Items currently held (exact from either side's own thread when the other side is idle,
  /// otherwise a snapshot).  Real-time safe.
  std::size_t size_approx() const noexcept {
    const std::uint64_t r = read_.load(std::memory_order_acquire);
    const std::uint64_t w = write_.load(std::memory_order_acquire);
    return static_cast<std::size_t>(w - r);
  }
  bool empty_approx() const noexcept { return size_approx() == 0; }

  /// Items accepted by try_push since construction.  Real-time safe; any thread.
  std::uint64_t pushed() const noexcept { return write_.load(std::memory_order_acquire); }
  /// Items taken by try_pop since construction.  Real-time safe; any thread.
  std::uint64_t popped() const noexcept { return read_.load(std::memory_order_acquire); }
  /// Pushes refused because the ring was full (overruns).  Real-time safe; any thread.
  std::uint64_t rejected() const noexcept { return rejected_.load(std::memory_order_relaxed); }

 private:
  static std::size_t round_up_pow2(std::size_t n) {
    if (n == 0 || n > (std::size_t{1} << 40))
      throw std::invalid_argument("SpscRing: capacity " + std::to_string(n) +
                                  " must be between 1 and 2^40");
    std::size_t c = 2;
    while (c < n)
      c <<= 1;
    return c;
  }

  const std::size_t capacity_;
  const std::size_t mask_;
  std::unique_ptr<T[]> slots_;

  // Producer's line: its own count, its cached view of the consumer's count, the reject count.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> write_{0};
  std::uint64_t prod_cached_read_ = 0;
  std::atomic<std::uint64_t> rejected_{0};
  // Consumer's line.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> read_{0};
  std::uint64_t cons_cached_write_ = 0;
  // Padding so whatever follows the ring in memory does not share the consumer's line.
  char pad_[kCacheLineBytes - sizeof(std::atomic<std::uint64_t>) - sizeof(std::uint64_t)]{};
};

}  // namespace errsep::acq
