// RecordingWriter / RecordingReader: byte-exact round trips, truncated and corrupted files,
// seeking, and clear errors for files that are not recordings.
#include <tessera/messages/types.hpp>
#include <tessera/runtime/recording.hpp>

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>

using namespace tessera;
namespace fs = std::filesystem;

namespace {

struct Sent {
  std::uint32_t topic;
  Nanos stamp;
  std::vector<std::byte> bytes;  // standard framing
};

std::shared_ptr<const MessageStorage> blob(std::size_t payload, std::uint64_t seq,
                                           std::size_t hint) {
  Loan<msg::Blob> loan(hint);
  setHeader(loan->initHeader(), static_cast<Nanos>(seq) * 1000, "test", seq);
  auto data = loan->initPayload(static_cast<unsigned>(payload));
  for (std::size_t i = 0; i < payload; ++i) data[i] = static_cast<capnp::byte>((i * 7 + seq) % 251);
  return std::move(loan).seal();
}

std::shared_ptr<const MessageStorage> scan(std::uint64_t seq) {
  Loan<msg::LaserScan> loan(400 * 4 + 256);
  setHeader(loan->initHeader(), static_cast<Nanos>(seq), "laser", seq);
  auto r = loan->initRanges(400);
  for (unsigned i = 0; i < 400; ++i) r.set(i, 1.0f + 0.01f * static_cast<float>((i + seq) % 300));
  return std::move(loan).seal();
}

const std::vector<RecordingTopic> kTopics = {
    {"scan", messageTypeOf<msg::LaserScan>().id, messageTypeOf<msg::LaserScan>().name},
    {"blob", messageTypeOf<msg::Blob>().id, messageTypeOf<msg::Blob>().name},
};

// Writes `n` messages alternating scans and blobs of varied sizes (some multi-segment: the hint
// is too small for the payload, so Cap'n Proto adds segments).
std::vector<Sent> writeRecording(const fs::path& path, int n, RecordingWriterOptions options) {
  RecordingWriter writer(path.string(), kTopics, options);
  std::vector<Sent> sent;
  for (int i = 0; i < n; ++i) {
    const auto seq = static_cast<std::uint64_t>(i);
    auto m = i % 2 == 0 ? scan(seq) : blob(static_cast<std::size_t>(i * 37 % 3000), seq, 16);
    const std::uint32_t topic = i % 2 == 0 ? 0 : 1;
    const Nanos stamp = 1'000'000 + static_cast<Nanos>(i) * 10'000'000;
    writer.append(topic, stamp, *m);
    sent.push_back({topic, stamp, encodeMessage(*m)});
  }
  writer.close();
  return sent;
}

std::vector<RecordedMessage> readAll(RecordingReader& reader) {
  std::vector<RecordedMessage> out;
  RecordedMessage m;
  while (reader.next(m)) out.push_back(m);
  return out;
}

std::vector<unsigned char> fileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const fs::path& path, const std::vector<unsigned char>& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

// Offsets of the block headers, found by their magic (the test payloads never contain it).
std::vector<std::size_t> blockOffsets(const std::vector<unsigned char>& bytes) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i + 4 <= bytes.size(); ++i)
    if (bytes[i] == 'T' && bytes[i + 1] == 'B' && bytes[i + 2] == 'L' && bytes[i + 3] == 'K')
      out.push_back(i);
  return out;
}

std::uint32_t u32At(const std::vector<unsigned char>& b, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// The messages read must be exactly sent[first..], in order, byte for byte. One assertion per
// call (the truncation test makes thousands of calls).
void checkSame(const std::vector<RecordedMessage>& got, const std::vector<Sent>& sent,
               std::size_t first = 0) {
  REQUIRE(got.size() + first <= sent.size());
  std::size_t mismatch = got.size();
  for (std::size_t i = 0; i < got.size() && mismatch == got.size(); ++i) {
    const auto& want = sent[i + first];
    if (got[i].topic != want.topic || got[i].stamp != want.stamp ||
        encodeMessage(*got[i].message) != want.bytes)
      mismatch = i;
  }
  INFO("first message that differs: " << mismatch + first);
  CHECK(mismatch == got.size());
}

fs::path tempFile(const std::string& name) {
  const auto dir = fs::temp_directory_path() / "tessera_recording_test";
  fs::create_directories(dir);
  return dir / name;
}

RecordingWriterOptions smallBlocks(bool zstd) {
  RecordingWriterOptions o;
  o.block_bytes = 8 * 1024;
  o.compression = zstd ? RecordingWriterOptions::Compression::kZstd
                       : RecordingWriterOptions::Compression::kNone;
  return o;
}

}  // namespace

TEST_CASE("recording round trip is byte exact with and without zstd", "[recording]") {
  for (bool zstd : {false, true}) {
    INFO("zstd " << zstd);
    const auto path = tempFile(zstd ? "round_zstd.trec" : "round_raw.trec");
    const auto sent = writeRecording(path, 200, smallBlocks(zstd));
    RecordingReader reader(path.string());
    CHECK(reader.version() == kRecordingFormatVersion);
    CHECK(reader.indexed());
    REQUIRE(reader.topics().size() == 2);
    CHECK(reader.topics()[0].name == "scan");
    CHECK(reader.topics()[0].type_id == messageTypeOf<msg::LaserScan>().id);
    CHECK(reader.topics()[1].type_name == "Blob");
    CHECK(reader.messageCount() == 200);
    CHECK(reader.topicCounts() == std::vector<std::uint64_t>{100, 100});
    CHECK(reader.blockCount() > 5);
    CHECK(reader.firstStamp() == sent.front().stamp);
    CHECK(reader.lastStamp() == sent.back().stamp);
    const auto got = readAll(reader);
    REQUIRE(got.size() == sent.size());
    checkSame(got, sent);
    CHECK(reader.losses().empty());
    // Multi-segment messages went through too.
    bool multi = false;
    for (const auto& m : got) multi = multi || m.message->segments().size() > 1;
    CHECK(multi);
    if (zstd) CHECK(fs::file_size(path) < fs::file_size(tempFile("round_raw.trec")));
  }
}

TEST_CASE("a recording appears under its name only whole; until then it is readable as .partial",
          "[recording]") {
  const auto path = tempFile("whole.trec");
  fs::remove(path);
  const auto earlier = writeRecording(path, 10, smallBlocks(false));
  const auto earlier_bytes = fileBytes(path);
  {
    RecordingWriter writer(path.string(), kTopics, smallBlocks(true));
    CHECK(writer.partialPath() == path.string() + ".partial");
    std::vector<Sent> sent;
    for (int i = 0; i < 80; ++i) {
      auto m = scan(static_cast<std::uint64_t>(i));
      writer.append(0, i * 1000, *m);
      sent.push_back({0, i * 1000, encodeMessage(*m)});
    }
    writer.flush();
    // A reader of `path` meanwhile sees the earlier whole recording; the one being written (as
    // a crash would leave it) is read from its .partial name by scanning its blocks.
    CHECK(fileBytes(path) == earlier_bytes);
    RecordingReader partial(writer.partialPath());
    CHECK_FALSE(partial.indexed());
    checkSame(readAll(partial), sent, 0);
    writer.close();
    CHECK_FALSE(fs::exists(writer.partialPath()));
    RecordingReader whole(path.string());
    CHECK(whole.indexed());
    checkSame(readAll(whole), sent, 0);
  }
  CHECK(earlier.size() == 10);
  // A folder that does not exist: the error names the file.
  CHECK_THROWS_WITH(RecordingWriter("/nonexistent/dir/x.trec", kTopics),
                    Catch::Contains("/nonexistent/dir/x.trec"));
}

TEST_CASE("recording reader filters topics and seeks by time", "[recording]") {
  const auto path = tempFile("seek.trec");
  const auto sent = writeRecording(path, 120, smallBlocks(true));
  RecordingReaderOptions only_blobs;
  only_blobs.topics = {"blob"};
  RecordingReader blobs(path.string(), only_blobs);
  const auto got = readAll(blobs);
  REQUIRE(got.size() == 60);
  for (const auto& m : got) CHECK(m.topic == 1);

  RecordingReader reader(path.string());
  const Nanos t = sent[77].stamp;
  reader.seek(t);
  const auto after = readAll(reader);
  REQUIRE(after.size() == sent.size() - 77);
  checkSame(after, sent, 77);

  only_blobs.topics = {"nope"};
  CHECK_THROWS_WITH(RecordingReader(path.string(), only_blobs),
                    Catch::Contains("no topic 'nope'") && Catch::Contains("scan, blob"));
}

TEST_CASE("a truncated recording replays its intact prefix and reports the cut block",
          "[recording]") {
  for (bool zstd : {false, true}) {
    INFO("zstd " << zstd);
    const auto path = tempFile("full.trec");
    const auto sent = writeRecording(path, 150, smallBlocks(zstd));
    const auto full = fileBytes(path);
    const auto blocks = blockOffsets(full);
    REQUIRE(blocks.size() > 4);
    // Messages before each block, from the record counts in the block headers.
    std::vector<std::size_t> before{0};
    for (auto b : blocks) before.push_back(before.back() + u32At(full, b + 24));
    REQUIRE(before.back() == sent.size());

    // Cuts around every block boundary (inside headers and payloads), in the index and footer,
    // and every 401 bytes.
    std::set<std::size_t> cuts;
    for (auto b : blocks)
      for (std::size_t d : {0, 1, 4, 30, 55, 56, 57, 200}) cuts.insert(b + d), cuts.insert(b - d);
    const std::size_t blocks_end = blocks.back() + 56 + u32At(full, blocks.back() + 8);
    for (std::size_t c = blocks_end; c < full.size(); c += 9) cuts.insert(c);
    for (std::size_t c = blocks[0]; c < full.size(); c += 401) cuts.insert(c);
    for (std::size_t cut : cuts) {
      if (cut < blocks[0] || cut >= full.size()) continue;
      INFO("cut at " << cut);
      auto reader = RecordingReader::fromBytes(
          "cut.trec", std::vector<unsigned char>(full.begin(), full.begin() + cut));
      CHECK_FALSE(reader.indexed());
      const auto got = readAll(reader);
      checkSame(got, sent);
      // The intact prefix is every block that ends before the cut.
      std::size_t whole = 0;
      while (whole < blocks.size() &&
             (whole + 1 < blocks.size() ? blocks[whole + 1] : full.size()) <= cut)
        ++whole;
      if (cut >= blocks_end) {
        // Every block is whole; the damaged index tail is noted without messages lost.
        CHECK(got.size() == sent.size());
        for (const auto& l : reader.losses()) CHECK(l.messages.value_or(0) == 0);
      } else {
        CHECK(got.size() == before[whole]);
        if (cut > blocks[whole]) {
          REQUIRE(reader.losses().size() == 1);
          const auto& loss = reader.losses()[0];
          CHECK(loss.offset == blocks[whole]);
          CHECK(loss.bytes == cut - blocks[whole]);
          if (cut >= blocks[whole] + 56) {
            CHECK(loss.messages == before[whole + 1] - before[whole]);
            CHECK_THAT(loss.what, Catch::Contains("truncated"));
          }
        } else {
          CHECK(reader.losses().empty());
        }
      }
    }
  }
}

TEST_CASE("a corrupted block costs only its own messages and is reported with offset and count",
          "[recording]") {
  for (bool zstd : {false, true}) {
    for (bool with_index : {true, false}) {
      INFO("zstd " << zstd << ", index " << with_index);
      const auto path = tempFile("corrupt.trec");
      const auto sent = writeRecording(path, 150, smallBlocks(zstd));
      const auto full = fileBytes(path);
      const auto blocks = blockOffsets(full);
      REQUIRE(blocks.size() > 4);
      std::vector<std::size_t> before{0};
      for (auto b : blocks) before.push_back(before.back() + u32At(full, b + 24));
      const std::size_t bad = 2;
      const std::size_t lost = before[bad + 1] - before[bad];

      // Without the index: the file as a crashed recorder leaves it (blocks only).
      auto damaged = full;
      if (!with_index) damaged.resize(blocks.back() + 56 + u32At(full, blocks.back() + 8));

      {  // payload checksum
        auto bytes = damaged;
        bytes[blocks[bad] + 56 + 100] ^= 0x5a;
        writeBytes(path, bytes);
        RecordingReader reader(path.string());
        CHECK(reader.indexed() == with_index);
        const auto got = readAll(reader);
        REQUIRE(got.size() == sent.size() - lost);
        checkSame(std::vector<RecordedMessage>(got.begin(), got.begin() + before[bad]), sent);
        checkSame(std::vector<RecordedMessage>(got.begin() + before[bad], got.end()), sent,
                  before[bad + 1]);
        REQUIRE(reader.losses().size() == 1);
        const auto& loss = reader.losses()[0];
        CHECK(loss.offset == blocks[bad]);
        CHECK(loss.bytes == blocks[bad + 1] - blocks[bad]);
        CHECK(loss.messages == lost);
        CHECK_THAT(loss.what, Catch::Contains("payload checksum mismatch"));
        CHECK_THAT(loss.describe(), Catch::Contains("byte " + std::to_string(blocks[bad])) &&
                                        Catch::Contains(std::to_string(lost) + " messages lost"));
      }
      {  // block length
        auto bytes = damaged;
        bytes[blocks[bad] + 9] ^= 0x01;  // stored payload size, covered by the header checksum
        writeBytes(path, bytes);
        RecordingReader reader(path.string());
        const auto got = readAll(reader);
        // Later blocks are found again (through the index, or by resynchronising on a header).
        REQUIRE(got.size() == sent.size() - lost);
        checkSame(std::vector<RecordedMessage>(got.begin() + before[bad], got.end()), sent,
                  before[bad + 1]);
        REQUIRE(reader.losses().size() == 1);
        const auto& loss = reader.losses()[0];
        CHECK(loss.offset == blocks[bad]);
        CHECK(loss.bytes == blocks[bad + 1] - blocks[bad]);
        CHECK_THAT(loss.what, Catch::Contains("block header checksum mismatch"));
        // The index knows how many messages the block held; a scan cannot.
        if (with_index)
          CHECK(loss.messages == lost);
        else
          CHECK_FALSE(loss.messages.has_value());
      }
    }
  }
}

TEST_CASE("files that are not recordings give clear errors", "[recording]") {
  const auto path = tempFile("bad.trec");
  writeBytes(
      path, {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd', '\n', 'x', 'y', 'z', '!', '!'});
  CHECK_THROWS_WITH(RecordingReader(path.string()),
                    Catch::Contains("bad.trec") && Catch::Contains("not a Tessera recording") &&
                        Catch::Contains("byte 0"));
  writeBytes(path, {});
  CHECK_THROWS_WITH(RecordingReader(path.string()), Catch::Contains("too short"));
  CHECK_THROWS_WITH(RecordingReader((path.string() + ".missing")), Catch::Contains("cannot open"));

  writeRecording(path, 10, smallBlocks(false));
  auto bytes = fileBytes(path);
  auto future = bytes;
  future[8] = 2;  // format version
  writeBytes(path, future);
  CHECK_THROWS_WITH(RecordingReader(path.string()), Catch::Contains("byte 8") &&
                                                        Catch::Contains("version 2") &&
                                                        Catch::Contains("reads version 1"));
  auto topic_table = bytes;
  topic_table[24] ^= 0x20;  // a letter of the first topic name
  writeBytes(path, topic_table);
  CHECK_THROWS_WITH(RecordingReader(path.string()),
                    Catch::Contains("file header checksum mismatch"));
}

TEST_CASE("recording reader survives random damage without crashing", "[recording]") {
  const auto path = tempFile("fuzz.trec");
  writeRecording(path, 60, smallBlocks(true));
  const auto full = fileBytes(path);
  std::uint64_t state = 12345;
  auto rnd = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return state >> 33;
  };
  std::size_t runs_with_losses = 0;
  for (int trial = 0; trial < 300; ++trial) {
    auto bytes = full;
    const int flips = 1 + static_cast<int>(rnd() % 8);
    for (int f = 0; f < flips; ++f)
      bytes[rnd() % bytes.size()] ^= static_cast<unsigned char>(1 + rnd() % 255);
    if (rnd() % 3 == 0) bytes.resize(rnd() % bytes.size());
    try {
      auto reader = RecordingReader::fromBytes("fuzz", bytes);
      const auto got = readAll(reader);
      CHECK(got.size() <= 60);
      runs_with_losses += reader.losses().empty() ? 0 : 1;
    } catch (const RecordingError&) {
      // A damaged file header is the one fatal case.
    }
  }
  CHECK(runs_with_losses > 100);
}
