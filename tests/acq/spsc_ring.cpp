#include "errsep/acq/spsc_ring.hpp"

#include <catch2/catch.hpp>
#include <cstdint>
#include <thread>

#include "errsep/acq/sample.hpp"

using errsep::acq::Sample;
using errsep::acq::SpscRing;

TEST_CASE("capacity is rounded up to a power of two and 0 is refused") {
  CHECK(SpscRing<int>(1).capacity() == 2);
  CHECK(SpscRing<int>(5).capacity() == 8);
  CHECK(SpscRing<int>(1024).capacity() == 1024);
  CHECK_THROWS_AS(SpscRing<int>(0), std::invalid_argument);
}

TEST_CASE("single thread: FIFO order, full ring refuses and counts, empty ring pops nothing") {
  SpscRing<int> ring(4);
  int out = -1;
  CHECK_FALSE(ring.try_pop(out));
  for (int i = 0; i < 4; ++i)
    CHECK(ring.try_push(i));
  CHECK(ring.size_approx() == 4);
  CHECK_FALSE(ring.try_push(99));
  CHECK_FALSE(ring.try_push(100));
  CHECK(ring.rejected() == 2);
  CHECK(ring.pushed() == 4);
  for (int i = 0; i < 4; ++i) {
    REQUIRE(ring.try_pop(out));
    CHECK(out == i);
  }
  CHECK_FALSE(ring.try_pop(out));
  CHECK(ring.popped() == 4);
  // Wrap around many times: indices are monotonic counters masked into the slots.
  for (int i = 0; i < 1000; ++i) {
    REQUIRE(ring.try_push(i));
    REQUIRE(ring.try_push(i + 1));
    REQUIRE(ring.try_pop(out));
    CHECK(out == i);
    REQUIRE(ring.try_pop(out));
    CHECK(out == i + 1);
  }
  CHECK(ring.rejected() == 2);
}

TEST_CASE("two threads: every item arrives once, in order, with its content intact") {
  // A small ring forces the producer to hit "full" often and the consumer to hit "empty" often,
  // exercising both cached-index refresh paths under contention.
  constexpr std::uint64_t kItems = 500'000;
  SpscRing<Sample> ring(64);
  std::uint64_t refused = 0;
  std::thread producer([&] {
    Sample s;
    for (std::uint64_t i = 0; i < kItems;) {
      s.seq = i;
      s.t_ns = static_cast<std::int64_t>(i * 3);
      s.value = static_cast<double>(i) * 0.5;
      s.channel = static_cast<std::uint16_t>(i % 7);
      if (ring.try_push(s))
        ++i;
      else if (++refused % 64 == 0)  // retry the same item: this test checks delivery
        std::this_thread::yield();   // (yield now and then: the machine may be shared)
    }
  });
  std::uint64_t expected = 0, bad_order = 0, bad_content = 0;
  Sample got;
  std::uint64_t empty = 0;
  while (expected < kItems) {
    if (!ring.try_pop(got)) {
      if (++empty % 64 == 0) std::this_thread::yield();
      continue;
    }
    if (got.seq != expected) ++bad_order;
    if (got.t_ns != static_cast<std::int64_t>(got.seq * 3) ||
        got.value != static_cast<double>(got.seq) * 0.5 || got.channel != got.seq % 7)
      ++bad_content;
    expected = got.seq + 1;
  }
  producer.join();
  CHECK(bad_order == 0);
  CHECK(bad_content == 0);
  CHECK(ring.pushed() == kItems);
  CHECK(ring.popped() == kItems);
  CHECK(ring.rejected() == refused);
  CHECK_FALSE(ring.try_pop(got));
}

TEST_CASE("two threads, producer never waits: accepted + rejected == offered, accepted in order") {
  // The sampler's policy: a full ring drops the new item and counts it.  What the consumer sees
  // must then be a strictly increasing subsequence, and the counts must add up exactly.
  constexpr std::uint64_t kOffered = 500'000;
  SpscRing<std::uint64_t> ring(128);
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kOffered; ++i)
      (void)ring.try_push(i);
  });
  std::uint64_t received = 0, last = 0, not_increasing = 0;
  bool first = true;
  std::uint64_t v = 0;
  for (;;) {
    if (ring.try_pop(v)) {
      if (!first && v <= last) ++not_increasing;
      first = false;
      last = v;
      ++received;
    } else if (ring.pushed() + ring.rejected() == kOffered && ring.empty_approx()) {
      break;
    }
  }
  producer.join();
  CHECK(not_increasing == 0);
  CHECK(received == ring.pushed());
  CHECK(received + ring.rejected() == kOffered);
}
