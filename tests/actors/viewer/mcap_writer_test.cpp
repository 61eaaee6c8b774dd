// Tests for the MCAP writer: the file read back record by record (magic, header, chunks and
// their CRCs, message indexes, summary offsets, footer and summary CRC), and its errors.
#include <tessera/viewer/mcap_writer.hpp>

#include <zlib.h>
#include <zstd.h>
#include <catch2/catch.hpp>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

using namespace tessera::viewer;
namespace fs = std::filesystem;

namespace {

std::vector<std::uint8_t> slurpBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Little-endian reads over a byte range, failing the test on overrun.
struct Cursor {
  const std::uint8_t* p;
  const std::uint8_t* end;
  template <class T>
  T num() {
    REQUIRE(static_cast<std::size_t>(end - p) >= sizeof(T));
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) v |= std::uint64_t{p[i]} << (8 * i);
    p += sizeof(T);
    return static_cast<T>(v);
  }
  std::string str() {
    const auto n = num<std::uint32_t>();
    REQUIRE(static_cast<std::size_t>(end - p) >= n);
    std::string s(reinterpret_cast<const char*>(p), n);
    p += n;
    return s;
  }
};

struct Record {
  std::uint8_t op;
  std::uint64_t offset;  ///< of the opcode in its buffer
  const std::uint8_t* content;
  std::uint64_t length;
};

std::vector<Record> records(const std::uint8_t* begin, const std::uint8_t* end) {
  std::vector<Record> out;
  Cursor c{begin, end};
  while (c.p < c.end) {
    const auto offset = static_cast<std::uint64_t>(c.p - begin);
    const auto op = c.num<std::uint8_t>();
    const auto len = c.num<std::uint64_t>();
    REQUIRE(static_cast<std::uint64_t>(c.end - c.p) >= len);
    out.push_back({op, offset, c.p, len});
    c.p += len;
  }
  return out;
}

const std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "tessera_mcap_writer_test";
  fs::create_directories(dir);
  return dir / name;
}

}  // namespace

TEST_CASE("an MCAP file reads back: chunks, indexes, summary and CRCs", "[viewer][mcap]") {
  const bool zstd = GENERATE(false, true);
  const fs::path path = scratch(zstd ? "z.mcap" : "plain.mcap");
  McapWriterOptions o;
  o.compression =
      zstd ? McapWriterOptions::Compression::kZstd : McapWriterOptions::Compression::kNone;
  o.chunk_bytes = 200;  // several chunks
  McapWriter w(path.string(), o);
  const auto schema = w.addSchema("foxglove.PoseInFrame", "jsonschema", R"({"type":"object"})");
  const auto a = w.addChannel(schema, "pose", "json", {{"k", "v"}});
  const auto b = w.addChannel(0, "status", "json");
  for (int i = 0; i < 20; ++i)
    w.write(i % 3 == 0 ? b : a, 1000 + static_cast<std::uint64_t>(i) * 10,
            R"({"i":)" + std::to_string(i) + "}");
  w.close();
  CHECK(w.stats().messages == 20);
  CHECK(w.stats().chunks > 2);

  const std::vector<std::uint8_t> f = slurpBytes(path);
  REQUIRE(f.size() > 16);
  CHECK(std::memcmp(f.data(), kMagic, 8) == 0);
  CHECK(std::memcmp(f.data() + f.size() - 8, kMagic, 8) == 0);
  CHECK(w.stats().file_bytes == f.size());

  // Footer: the last record before the trailing magic.
  const std::uint8_t* footer = f.data() + f.size() - 8 - (1 + 8 + 20);
  REQUIRE(footer[0] == 0x02);
  Cursor fc{footer + 9, footer + 29};
  const auto summary_start = fc.num<std::uint64_t>();
  const auto summary_offset_start = fc.num<std::uint64_t>();
  const auto summary_crc = fc.num<std::uint32_t>();
  REQUIRE(summary_start < summary_offset_start);
  CHECK(summary_crc == crc32(0, f.data() + summary_start,
                             static_cast<uInt>(footer + 1 + 8 + 16 - (f.data() + summary_start))));

  // Data section: header, schema, channels, then chunks each followed by message indexes.
  const auto data = records(f.data() + 8, f.data() + summary_start);
  REQUIRE(data.size() > 4);
  CHECK(data[0].op == 0x01);
  Cursor h{data[0].content, data[0].content + data[0].length};
  CHECK(h.str().empty());
  CHECK(h.str() == "tessera");
  CHECK(data[1].op == 0x03);
  CHECK(data[2].op == 0x04);
  CHECK(data[3].op == 0x04);
  CHECK(data.back().op == 0x0F);
  std::map<std::uint16_t, int> per_channel;
  int chunks = 0;
  for (std::size_t i = 0; i < data.size(); ++i) {
    if (data[i].op != 0x06) continue;
    ++chunks;
    Cursor c{data[i].content, data[i].content + data[i].length};
    const auto start = c.num<std::uint64_t>(), end = c.num<std::uint64_t>();
    const auto size = c.num<std::uint64_t>();
    const auto crc = c.num<std::uint32_t>();
    const std::string compression = c.str();
    CHECK(compression == (zstd ? "zstd" : ""));
    const auto packed = c.num<std::uint64_t>();
    REQUIRE(static_cast<std::uint64_t>(c.end - c.p) == packed);
    std::vector<std::uint8_t> plain(size);
    if (zstd)
      REQUIRE(ZSTD_decompress(plain.data(), size, c.p, packed) == size);
    else
      std::memcpy(plain.data(), c.p, size);
    CHECK(crc == crc32(0, plain.data(), static_cast<uInt>(size)));
    // Message indexes right after the chunk point at its message records with their times.
    for (std::size_t j = i + 1; j < data.size() && data[j].op == 0x07; ++j) {
      Cursor mi{data[j].content, data[j].content + data[j].length};
      const auto channel = mi.num<std::uint16_t>();
      const auto bytes = mi.num<std::uint32_t>();
      REQUIRE(bytes % 16 == 0);
      for (std::uint32_t k = 0; k < bytes / 16; ++k) {
        const auto time = mi.num<std::uint64_t>(), at = mi.num<std::uint64_t>();
        REQUIRE(at + 9 + 22 <= size);
        CHECK(plain[at] == 0x05);
        Cursor m{plain.data() + at + 9, plain.data() + size};
        CHECK(m.num<std::uint16_t>() == channel);
        m.num<std::uint32_t>();
        CHECK(m.num<std::uint64_t>() == time);
        CHECK(time >= start);
        CHECK(time <= end);
        ++per_channel[channel];
      }
    }
  }
  CHECK(chunks == static_cast<int>(w.stats().chunks));
  CHECK(per_channel[a] == 13);
  CHECK(per_channel[b] == 7);

  // Summary offsets name the groups of the summary by opcode.
  const auto offsets = records(f.data() + summary_offset_start, footer);
  std::map<std::uint8_t, std::uint8_t> first_op_of_group;
  for (const auto& r : offsets) {
    REQUIRE(r.op == 0x0E);
    Cursor c{r.content, r.content + r.length};
    const auto group = c.num<std::uint8_t>();
    const auto start = c.num<std::uint64_t>();
    c.num<std::uint64_t>();
    first_op_of_group[group] = f[start];
  }
  for (const std::uint8_t op : {0x03, 0x04, 0x0B, 0x08}) CHECK(first_op_of_group[op] == op);
  // Statistics: counts and time range.
  for (const auto& r : records(f.data() + summary_start, f.data() + summary_offset_start)) {
    if (r.op != 0x0B) continue;
    Cursor c{r.content, r.content + r.length};
    CHECK(c.num<std::uint64_t>() == 20);
    CHECK(c.num<std::uint16_t>() == 1);
    CHECK(c.num<std::uint32_t>() == 2);
    c.num<std::uint32_t>();
    c.num<std::uint32_t>();
    CHECK(c.num<std::uint32_t>() == w.stats().chunks);
    CHECK(c.num<std::uint64_t>() == 1000);
    CHECK(c.num<std::uint64_t>() == 1190);
  }
}

TEST_CASE("the MCAP writer refuses unknown channels and schemas and unwritable paths",
          "[viewer][mcap]") {
  const fs::path path = scratch("errors.mcap");
  McapWriter w(path.string());
  CHECK_THROWS_AS(w.write(1, 0, "{}"), McapError);
  CHECK_THROWS_WITH(w.addChannel(3, "t", "json"), Catch::Contains("unknown schema 3"));
  const auto c = w.addChannel(0, "t", "json");
  w.write(c, 5, "{}");
  w.close();
  CHECK_THROWS_WITH(w.write(c, 6, "{}"), Catch::Contains("closed"));
  CHECK_THROWS_WITH(McapWriter("/nonexistent/dir/x.mcap"),
                    Catch::Contains("/nonexistent/dir/x.mcap"));
  // An empty file (no message) is still a whole MCAP file.
  const fs::path empty = scratch("empty.mcap");
  McapWriter(empty.string()).close();
  const auto f = slurpBytes(empty);
  REQUIRE(f.size() > 16);
  CHECK(std::memcmp(f.data() + f.size() - 8, kMagic, 8) == 0);
}

TEST_CASE("an MCAP file appears under its name only whole; an earlier one stays until then",
          "[viewer][mcap]") {
  const fs::path path = scratch("whole.mcap");
  {
    McapWriter first(path.string());
    first.write(first.addChannel(0, "t", "json"), 1, R"({"n":1})");
  }  // closed by the destructor
  const auto before = slurpBytes(path);
  REQUIRE(before.size() > 16);
  McapWriter w(path.string());
  const auto c = w.addChannel(0, "t", "json");
  for (int i = 0; i < 50; ++i) w.write(c, static_cast<std::uint64_t>(i), R"({"n":2})");
  CHECK(w.partialPath() == path.string() + ".partial");
  CHECK(fs::exists(w.partialPath()));
  CHECK(slurpBytes(path) == before);  // a reader of `path` sees the earlier whole file
  w.close();
  CHECK_FALSE(fs::exists(w.partialPath()));
  const auto after = slurpBytes(path);
  CHECK(after != before);
  CHECK(std::memcmp(after.data() + after.size() - 8, kMagic, 8) == 0);
}
