// Tests for MappedAllocator: values hold across growth, big blocks are mapped on their own and
// leave the process when freed, impossible sizes throw.
#include <tessera/memory/mapped_allocator.hpp>

#include <catch2/catch.hpp>

#include <cerrno>
#include <cstdint>
#include <numeric>
#include <vector>

#include <sys/mman.h>
#include <unistd.h>

using namespace tessera::memory;

namespace {

/// Whether every page of [p, p + bytes) is mapped (mincore fails with ENOMEM on unmapped pages).
bool mapped(const void* p, std::size_t bytes) {
  const auto page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  const auto start = reinterpret_cast<std::uintptr_t>(p) / page * page;
  std::vector<unsigned char> residency((bytes + page - 1) / page + 1);
  errno = 0;
  const int rc = mincore(reinterpret_cast<void*>(start), bytes, residency.data());
  return rc == 0;
}

}  // namespace

TEST_CASE("mapped vectors hold their values across growth", "[memory]") {
  MappedVector<std::uint16_t> v;
  for (std::uint16_t i = 0; i < 10; ++i) v.push_back(i);  // small blocks: operator new
  v.resize(std::size_t{1} << 20);                         // 2 MiB: a block of its own
  for (std::uint16_t i = 0; i < 10; ++i) CHECK(v[i] == i);
  CHECK(v.back() == 0);
  std::iota(v.begin(), v.end(), std::uint16_t{0});
  MappedVector<std::uint16_t> copy = v;
  CHECK(copy == v);
  CHECK(copy[(std::size_t{1} << 20) - 1] == static_cast<std::uint16_t>((1u << 20) - 1));
}

TEST_CASE("a big mapped block is page-aligned, zero-filled and unmapped when freed", "[memory]") {
  const std::size_t bytes = kMappedMinBytes * 16 + 123;
  auto* block = static_cast<unsigned char*>(allocateMapped(bytes));
  REQUIRE(block != nullptr);
  CHECK(reinterpret_cast<std::uintptr_t>(block) %
            static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE)) ==
        0);
  CHECK(block[0] == 0);
  CHECK(block[bytes - 1] == 0);
  block[bytes / 2] = 7;
  CHECK(mapped(block, bytes));
  deallocateMapped(block, bytes);
  CHECK_FALSE(mapped(block, bytes));  // gone from the process, not a hole in malloc's heap
  CHECK(errno == ENOMEM);
}

TEST_CASE("an impossible mapped allocation throws instead of returning a short block", "[memory]") {
  MappedAllocator<std::uint64_t> a;
  CHECK_THROWS_AS(a.allocate(static_cast<std::size_t>(-1) / 4), std::bad_array_new_length);
  CHECK_THROWS_AS(allocateMapped(static_cast<std::size_t>(-1) - 10), std::bad_alloc);
  deallocateMapped(nullptr, kMappedMinBytes);  // freeing nothing is allowed
}
