// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's frame queue (firmware/daemon/include/tofmat/daemon/bounded_queue.hpp):
// first in, first out; when full, push() drops the oldest item and counts it
// (the camera is never blocked); pop() returns an item, or nothing after its
// timeout or once the queue is closed and empty; under concurrent producers
// and a consumer nothing is lost beyond the counted drops; push_wait() (a
// producer that must lose nothing) waits for room and gives up on stop or close.
// Waits are bounded (kHangMs) only so that a broken queue fails instead of
// hanging; nothing here asserts how fast anything is.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <future>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "tofmat/daemon/bounded_queue.hpp"

namespace {

using tofmat::daemon::BoundedQueue;
using namespace std::chrono_literals;

// How long a pop that should return at once may take before the test calls it hung.
constexpr auto kHang = 10s;
// A pop timeout far beyond kHang: a pop that returns within kHang was woken, not timed out.
constexpr auto kLongPop = std::chrono::milliseconds(30'000);

template <typename T>
std::vector<T> drain(BoundedQueue<T>& q) {
  std::vector<T> out;
  while (auto item = q.pop(0ms)) out.push_back(std::move(*item));
  return out;
}

TEST(BoundedQueue, PopsInTheOrderPushed) {
  BoundedQueue<int> q(8);
  for (int i = 1; i <= 5; ++i) q.push(i);
  EXPECT_EQ(q.size(), 5u);
  EXPECT_EQ(drain(q), (std::vector<int>{1, 2, 3, 4, 5}));
  EXPECT_EQ(q.size(), 0u);
  EXPECT_EQ(q.dropped(), 0u);
}

TEST(BoundedQueue, FullQueueDropsTheOldestAndCountsEveryDrop) {
  BoundedQueue<int> q(3);
  for (int i = 1; i <= 3; ++i) q.push(i);
  EXPECT_EQ(q.dropped(), 0u);  // exactly full is not over-full
  for (int i = 4; i <= 7; ++i) {
    q.push(i);
    EXPECT_EQ(q.dropped(), static_cast<std::uint64_t>(i - 3));
    EXPECT_EQ(q.size(), 3u);
  }
  EXPECT_EQ(drain(q), (std::vector<int>{5, 6, 7}));
  // The count is a running total: popping does not reset it, and a queue with
  // room again drops nothing more.
  q.push(8);
  EXPECT_EQ(q.dropped(), 4u);
  EXPECT_EQ(*q.pop(0ms), 8);
}

TEST(BoundedQueue, CapacityOneKeepsOnlyTheNewest) {
  BoundedQueue<std::string> q(1);
  q.push("a");
  q.push("b");
  q.push("c");
  EXPECT_EQ(q.dropped(), 2u);
  EXPECT_EQ(q.size(), 1u);
  EXPECT_EQ(drain(q), (std::vector<std::string>{"c"}));
}

TEST(BoundedQueue, CapacityZeroIsTreatedAsOne) {
  // A queue that could hold nothing would drop every frame: the constructor makes it 1.
  BoundedQueue<int> q(0);
  q.push(1);
  EXPECT_EQ(q.size(), 1u);
  EXPECT_EQ(q.dropped(), 0u);
  q.push(2);
  EXPECT_EQ(q.dropped(), 1u);
  EXPECT_EQ(drain(q), (std::vector<int>{2}));
}

TEST(BoundedQueue, HoldsMoveOnlyItems) {
  // Frames are moved through, never copied (4 MB each).
  BoundedQueue<std::unique_ptr<int>> q(2);
  q.push(std::make_unique<int>(1));
  q.push(std::make_unique<int>(2));
  q.push(std::make_unique<int>(3));
  auto first = q.pop(0ms);
  ASSERT_TRUE(first && *first);
  EXPECT_EQ(**first, 2);
  EXPECT_EQ(q.dropped(), 1u);
}

TEST(BoundedQueue, PopOnAnEmptyQueueReturnsNothingAfterItsTimeout) {
  BoundedQueue<int> q(2);
  EXPECT_FALSE(q.pop(0ms));
  EXPECT_FALSE(q.pop(20ms));
  // An item pushed afterwards is still there (a timeout is not a close).
  q.push(5);
  EXPECT_EQ(q.pop(0ms), std::optional<int>(5));
}

// A pop(kLongPop) on another thread, started and (most likely) blocked by the time this returns.
std::future<std::optional<int>> waiting_pop(BoundedQueue<int>& q) {
  std::promise<void> waiting;
  auto popped = std::async(std::launch::async, [&q, &waiting] {
    waiting.set_value();
    return q.pop(kLongPop);
  });
  waiting.get_future().wait();
  std::this_thread::sleep_for(20ms);  // (likely already blocked in pop; correct either way)
  return popped;
}

TEST(BoundedQueue, PushWakesAWaitingPop) {
  BoundedQueue<int> q(2);
  auto popped = waiting_pop(q);
  q.push(42);
  ASSERT_EQ(popped.wait_for(kHang), std::future_status::ready) << "push did not wake the waiting pop";
  EXPECT_EQ(popped.get(), std::optional<int>(42));
}

TEST(BoundedQueue, CloseWakesAWaitingPopWithNothing) {
  BoundedQueue<int> q(2);
  auto popped = waiting_pop(q);
  q.close();
  ASSERT_EQ(popped.wait_for(kHang), std::future_status::ready) << "close did not wake the waiting pop";
  EXPECT_FALSE(popped.get());
}

TEST(BoundedQueue, ClosedQueueHandsOutWhatItHoldsThenNothingAtOnce) {
  BoundedQueue<int> q(4);
  q.push(1);
  q.push(2);
  q.close();
  auto rest = std::async(std::launch::async, [&] {
    std::vector<std::optional<int>> out;
    out.reserve(3);
    for (int i = 0; i < 3; ++i) out.push_back(q.pop(kLongPop));
    return out;
  });
  ASSERT_EQ(rest.wait_for(kHang), std::future_status::ready) << "pop on a closed, empty queue waited";
  EXPECT_EQ(rest.get(), (std::vector<std::optional<int>>{1, 2, std::nullopt}));
}

// Producers push numbered items as fast as they can while one consumer pops:
// every item is either received or counted as dropped, none twice, and each
// producer's items arrive in the order it pushed them.
void producers_and_consumer(std::size_t capacity, int producers, int per_producer, bool slow_consumer,
                            std::uint64_t* dropped_out) {
  BoundedQueue<std::pair<int, int>> q(capacity);  // (producer, number)
  auto consumer = std::async(std::launch::async, [&] {
    std::vector<std::pair<int, int>> got;
    while (auto item = q.pop(kLongPop)) {
      got.push_back(*item);
      if (slow_consumer && got.size() % 64 == 0) std::this_thread::sleep_for(1ms);
    }
    return got;
  });
  std::vector<std::thread> threads;
  threads.reserve(static_cast<std::size_t>(producers));
  for (int p = 0; p < producers; ++p)
    threads.emplace_back([&q, p, per_producer] {
      for (int i = 0; i < per_producer; ++i) q.push({p, i});
    });
  for (auto& t : threads) t.join();
  q.close();
  ASSERT_EQ(consumer.wait_for(kHang), std::future_status::ready) << "the consumer did not finish after close";
  const auto got = consumer.get();

  const std::uint64_t total = static_cast<std::uint64_t>(producers) * static_cast<std::uint64_t>(per_producer);
  EXPECT_EQ(got.size() + q.dropped(), total) << "items lost beyond the counted drops";
  std::set<std::pair<int, int>> unique(got.begin(), got.end());
  EXPECT_EQ(unique.size(), got.size()) << "an item came out twice";
  std::vector<int> last(static_cast<std::size_t>(producers), -1);
  for (const auto& [p, i] : got) {
    ASSERT_GE(p, 0);
    ASSERT_LT(p, producers);
    EXPECT_GT(i, last[static_cast<std::size_t>(p)]) << "producer " << p << "'s items out of order";
    last[static_cast<std::size_t>(p)] = i;
  }
  // With one producer the last item pushed is the newest of all: drops only
  // ever take the oldest, so it always arrives. (With several, another
  // producer's later pushes may legitimately push it out.)
  if (producers == 1) {
    EXPECT_EQ(last[0], per_producer - 1) << "the newest item was dropped";
  }
  *dropped_out = q.dropped();
}

TEST(BoundedQueue, ConcurrentProducersLoseNothingBeyondTheCountedDrops) {
  std::uint64_t dropped = 0;
  producers_and_consumer(4, 3, 20000, /*slow_consumer=*/true, &dropped);
  // (How many drop depends on scheduling; that the count balances is the point.)
  RecordProperty("dropped", std::to_string(dropped));
}

TEST(BoundedQueue, OneFastProducerAndASlowConsumerKeepTheNewestItem) {
  std::uint64_t dropped = 0;
  producers_and_consumer(2, 1, 20000, /*slow_consumer=*/true, &dropped);
}

TEST(BoundedQueue, ConcurrentProducersWithRoomForEverythingDropNothing) {
  std::uint64_t dropped = 1;
  producers_and_consumer(3 * 5000, 3, 5000, /*slow_consumer=*/false, &dropped);
  EXPECT_EQ(dropped, 0u);
}

// push_wait(): the producer that must lose nothing (a replay) waits for room
// instead of dropping, and gives up when stopped or closed.

TEST(BoundedQueuePushWait, QueuesAtOnceWhenThereIsRoom) {
  BoundedQueue<int> q(2);
  const std::atomic<bool> stop{false};
  EXPECT_TRUE(q.push_wait(1, stop));
  EXPECT_TRUE(q.push_wait(2, stop));
  EXPECT_EQ(drain(q), (std::vector<int>{1, 2}));
  EXPECT_EQ(q.dropped(), 0u);
}

TEST(BoundedQueuePushWait, WaitsForAPopInsteadOfDropping) {
  BoundedQueue<int> q(1);
  std::atomic<bool> stop{false};
  q.push(1);
  auto pushed = std::async(std::launch::async, [&] { return q.push_wait(2, stop); });
  std::this_thread::sleep_for(20ms);  // (likely already waiting; correct either way)
  EXPECT_EQ(q.pop(0ms), std::optional<int>(1));
  ASSERT_EQ(pushed.wait_for(kHang), std::future_status::ready) << "a pop did not make room for the waiting push";
  EXPECT_TRUE(pushed.get());
  EXPECT_EQ(drain(q), (std::vector<int>{2}));
  EXPECT_EQ(q.dropped(), 0u);
}

TEST(BoundedQueuePushWait, GivesUpWhenStopIsSetOrTheQueueIsClosed) {
  for (const bool by_close : {false, true}) {
    BoundedQueue<int> q(1);
    std::atomic<bool> stop{false};
    q.push(1);
    auto pushed = std::async(std::launch::async, [&] { return q.push_wait(2, stop); });
    std::this_thread::sleep_for(20ms);
    if (by_close) {
      q.close();
    } else {
      stop = true;  // nobody closes the queue: the wait must notice stop itself
    }
    ASSERT_EQ(pushed.wait_for(kHang), std::future_status::ready)
        << (by_close ? "close" : "stop") << " did not end the wait";
    EXPECT_FALSE(pushed.get()) << (by_close ? "close" : "stop");
    EXPECT_EQ(drain(q), (std::vector<int>{1})) << "the refused item was queued anyway";
    EXPECT_EQ(q.dropped(), 0u);
  }
}

TEST(BoundedQueuePushWait, AProducerThatWaitsLosesNothingToASlowConsumer) {
  BoundedQueue<int> q(2);
  const std::atomic<bool> stop{false};
  constexpr int kItems = 2000;
  auto consumer = std::async(std::launch::async, [&] {
    std::vector<int> got;
    while (auto item = q.pop(kLongPop)) {
      got.push_back(*item);
      if (got.size() % 64 == 0) std::this_thread::sleep_for(1ms);
    }
    return got;
  });
  for (int i = 0; i < kItems; ++i) ASSERT_TRUE(q.push_wait(i, stop));
  q.close();
  ASSERT_EQ(consumer.wait_for(kHang), std::future_status::ready);
  const auto got = consumer.get();
  ASSERT_EQ(got.size(), static_cast<std::size_t>(kItems));
  for (int i = 0; i < kItems; ++i) ASSERT_EQ(got[static_cast<std::size_t>(i)], i);
  EXPECT_EQ(q.dropped(), 0u);
}

}  // namespace
