// Tests for LargePageAllocator: small and large blocks hold their values, large ones are aligned.
#include <tessera/memory/large_page_allocator.hpp>

#include <catch2/catch.hpp>

#include <cstdint>
#include <numeric>

using namespace tessera::memory;

TEST_CASE("large-page vectors hold their values across growth, and large blocks are aligned",
          "[memory]") {
  LargePageVector<std::uint32_t> v;
  for (std::uint32_t i = 0; i < 10; ++i) v.push_back(i);  // small blocks: operator new
  v.resize(std::size_t{3} << 20);                         // 12 MiB: an aligned, advised block
  CHECK(reinterpret_cast<std::uintptr_t>(v.data()) % kLargePageBytes == 0);
  for (std::uint32_t i = 0; i < 10; ++i) CHECK(v[i] == i);
  CHECK(v.back() == 0);
  std::iota(v.begin(), v.end(), 0u);
  LargePageVector<std::uint32_t> copy = v;
  CHECK(copy == v);
  v.clear();
  v.shrink_to_fit();  // back to no block: the large one is freed with the size it came with
  CHECK(v.capacity() == 0);
  CHECK(copy[(std::size_t{3} << 20) - 1] == (3u << 20) - 1);
}

TEST_CASE("an impossible large-page allocation throws instead of returning a short block",
          "[memory]") {
  LargePageAllocator<std::uint64_t> a;
  CHECK_THROWS_AS(a.allocate(static_cast<std::size_t>(-1) / 4), std::bad_array_new_length);
  CHECK_THROWS_AS(allocateLarge(static_cast<std::size_t>(-1) - 10), std::bad_alloc);
}
