// Tests for the planner's open list: pops in key order against a binary heap over many laps of
// the ring, equal keys last in first out, keys out of range refused, reuse after clear/reset.
#include <tessera/navigation/bucket_queue.hpp>

#include <catch2/catch.hpp>

#include <functional>
#include <queue>
#include <random>
#include <stdexcept>
#include <vector>

using namespace tessera::navigation;

namespace {

/// Random pushes (keys in [last popped, last popped + span]) and pops on the queue and on a
/// binary heap; the popped keys must agree, and the queue must account for every entry.
void compareWithHeap(std::int64_t span, std::uint64_t seed, int operations) {
  MonotoneBucketQueue queue(span);
  std::priority_queue<std::int64_t, std::vector<std::int64_t>, std::greater<>> reference;
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::int64_t> offset(0, span);
  std::bernoulli_distribution push(0.55);
  std::int64_t last = 12345;
  queue.push(last, -1);  // the first push sets the base
  reference.push(last);
  for (int op = 0; op < operations; ++op) {
    if (reference.empty() || push(rng)) {
      const std::int64_t key = last + offset(rng);
      queue.push(key, op);
      reference.push(key);
    } else {
      REQUIRE_FALSE(queue.empty());
      const auto got = queue.pop();
      REQUIRE(got.key == reference.top());
      reference.pop();
      last = got.key;
    }
    REQUIRE(queue.size() == reference.size());
  }
  while (!reference.empty()) {
    REQUIRE(queue.pop().key == reference.top());
    reference.pop();
  }
  CHECK(queue.empty());
}

}  // namespace

TEST_CASE("the bucket queue pops keys in the order of a binary heap", "[navigation]") {
  SECTION("a span of a few buckets, many laps of the ring") {
    compareWithHeap(5, 1, 50000);
  }
  SECTION("a span filling the ring exactly") {
    compareWithHeap(63, 2, 50000);
  }
  SECTION("a span larger than one bitmap word") {
    compareWithHeap(1000, 3, 50000);
  }
  SECTION("a span of zero: every key equal") {
    compareWithHeap(0, 4, 2000);
  }
}

TEST_CASE("the bucket queue pops equal keys last in, first out", "[navigation]") {
  MonotoneBucketQueue queue(100);
  queue.push(20, 1);
  queue.push(25, 2);
  queue.push(20, 3);
  queue.push(25, 4);
  queue.push(20, 5);
  std::vector<std::int32_t> order;
  while (!queue.empty()) order.push_back(queue.pop().value);
  CHECK(order == std::vector<std::int32_t>{5, 3, 1, 4, 2});
}

TEST_CASE("the bucket queue keeps its last popped key when it runs empty", "[navigation]") {
  MonotoneBucketQueue queue(10);
  queue.push(50, 1);
  CHECK(queue.pop().key == 50);
  CHECK(queue.empty());
  // Children of the entry just popped may come in any order within the span.
  queue.push(58, 2);
  queue.push(51, 3);
  CHECK(queue.pop().value == 3);
  CHECK(queue.pop().value == 2);
}

TEST_CASE("the bucket queue refuses keys outside its window and a bad span", "[navigation]") {
  CHECK_THROWS_WITH(MonotoneBucketQueue(-1), Catch::Contains("span"));
  CHECK_THROWS_WITH(MonotoneBucketQueue(std::int64_t{1} << 24), Catch::Contains("span"));
  MonotoneBucketQueue queue(10);
  CHECK_THROWS_AS(queue.pop(), std::logic_error);
  queue.push(100, 1);
  CHECK_THROWS_WITH(queue.push(99, 2), Catch::Contains("key 99 outside [100, 110]"));
  CHECK_THROWS_WITH(queue.push(111, 2), Catch::Contains("key 111"));
  CHECK(queue.size() == 1);
  CHECK(queue.pop().value == 1);
}

TEST_CASE("the bucket queue can be cleared and reset for reuse", "[navigation]") {
  MonotoneBucketQueue queue(8);
  for (std::int64_t k = 1000; k < 1008; ++k) queue.push(k, static_cast<std::int32_t>(k));
  CHECK(queue.pop().key == 1000);
  queue.clear();
  CHECK(queue.empty());
  queue.push(7, 1);  // a new base below the keys seen before the clear
  queue.push(5 + 8, 2);
  CHECK(queue.pop().value == 1);
  CHECK(queue.pop().value == 2);
  queue.reset(500);
  CHECK(queue.span() == 500);
  queue.push(3000, 3);
  queue.push(3500, 4);
  queue.push(3001, 5);
  CHECK(queue.pop().value == 3);
  CHECK(queue.pop().value == 5);
  CHECK(queue.pop().value == 4);
}
