// SCIP 2.0 (Hokuyo URG/UTM): encoding, checksums, commands, and replies parsed from a byte
// stream that arrives in pieces, with garbage, corruption and truncation.
#include <tessera/drivers/scip.hpp>

#include <catch2/catch.hpp>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace scip_test {

namespace scip = tessera::drivers::scip;

std::vector<std::uint32_t> rampScan(std::size_t n) {
  std::vector<std::uint32_t> r(n);
  for (std::size_t k = 0; k < n; ++k) r[k] = static_cast<std::uint32_t>(20 + (k * 37) % 5580);
  return r;
}

TEST_CASE("scip encodes and decodes as the specification's examples", "[drivers][scip]") {
  CHECK(scip::encode(1234, 2) == "CB");
  CHECK(scip::encode(5432, 3) == "1Dh");
  CHECK(scip::decode("CB") == 1234u);
  CHECK(scip::decode("1Dh") == 5432u);
  CHECK(scip::checksum("00") == 'P');  // the status line "00P"
  for (const std::uint32_t v : {0u, 1u, 63u, 64u, 4095u, 262143u, 16777215u}) {
    const int chars = v < 4096 ? 2 : (v < 262144 ? 3 : 4);
    CHECK(scip::decode(scip::encode(v, chars)) == v);
  }
  CHECK_THROWS_WITH(scip::encode(4096, 2), Catch::Contains("does not fit"));
  CHECK_THROWS_WITH(scip::encode(1, 5), Catch::Contains("1..4"));
  CHECK_FALSE(scip::decode(""));
  CHECK_FALSE(scip::decode("00000"));
  CHECK_FALSE(scip::decode("0/"));  // 0x2F is below the encoding
  CHECK_FALSE(scip::decode("0p"));  // 0x70 is above it
}

TEST_CASE("scip scan commands are the specification's strings", "[drivers][scip]") {
  CHECK(scip::scanCommand(true, 44, 725, 0, 0, 1) == "MD0044072500001\n");
  CHECK(scip::scanCommand(false, 0, 768, 1) == "GD0000076801\n");
  CHECK(scip::scanCommand(true, 0, 768, 2, 0, 0, false) == "MS0000076802000\n");
  CHECK_THROWS_WITH(scip::scanCommand(true, 700, 44, 0), Catch::Contains("before the first"));
  CHECK_THROWS_WITH(scip::scanCommand(true, 0, 10000, 0), Catch::Contains("last"));
  CHECK_THROWS_WITH(scip::scanCommand(true, 0, 10, 0, 10), Catch::Contains("interval"));
}

TEST_CASE("scip replies are parsed from any split of the stream", "[drivers][scip]") {
  const auto ranges = rampScan(682);  // a URG-04LX scan, 3 characters each: 33 data lines
  const std::string stream = scip::encodeScanReply("MD0044072500001", "00", 0, {}, 3) +
                             scip::encodeScanReply("MD0044072500000", "99", 123456, ranges, 3);
  std::mt19937 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    scip::ReplyParser parser;
    std::vector<scip::Reply> replies;
    for (std::size_t at = 0; at < stream.size();) {
      const std::size_t n = std::min<std::size_t>(1 + rng() % 70, stream.size() - at);
      for (auto& r : parser.feed(std::string_view(stream).substr(at, n))) replies.push_back(r);
      at += n;
    }
    REQUIRE(replies.size() == 2);
    CHECK(replies[0].error.empty());
    CHECK(replies[0].status == "00");
    const auto ack = scip::decodeScan(replies[0], 3);
    CHECK_FALSE(ack.scan);
    CHECK(replies[1].echo == "MD0044072500000");
    const auto d = scip::decodeScan(replies[1], 3);
    INFO(d.error);
    REQUIRE(d.scan);
    CHECK(d.scan->timestamp_ms == 123456u);
    CHECK(d.scan->ranges == ranges);
    CHECK(parser.skippedBytes() == 0);
  }
}

TEST_CASE("scip garbage before a reply is skipped and counted", "[drivers][scip]") {
  const auto ranges = rampScan(100);
  scip::ReplyParser parser;
  auto out = parser.feed(std::string("\x01\xff noise\nzz\n\n") +
                         scip::encodeScanReply("GD0000009900", "00", 7, ranges, 3));
  REQUIRE(out.size() == 1);
  CHECK(parser.skippedBytes() == 12);
  const auto d = scip::decodeScan(out[0], 3);
  REQUIRE(d.scan);
  CHECK(d.scan->ranges == ranges);
  // A line that never ends (wrong baud rate) is dropped, and the next reply still comes through.
  out = parser.feed(std::string(300, '\x7f') + "\n" +
                    scip::encodeScanReply("GD0000009900", "00", 8, ranges, 3));
  REQUIRE(out.size() == 1);
  CHECK(parser.skippedBytes() > 300);
  CHECK(scip::decodeScan(out[0], 3).scan);
}

TEST_CASE("scip corrupt, truncated and refused replies are never scans", "[drivers][scip]") {
  const auto ranges = rampScan(200);
  const std::string good = scip::encodeScanReply("GD0000019900", "00", 9, ranges, 3);
  SECTION("a flipped data byte fails its line's checksum") {
    std::string bad = good;
    bad[bad.find('\n', bad.find('\n', bad.find('\n') + 1) + 1) + 10] ^= 0x01;
    scip::ReplyParser parser;
    const auto out = parser.feed(bad);
    REQUIRE(out.size() == 1);
    CHECK_THAT(out[0].error, Catch::Contains("line 4: checksum mismatch"));
    const auto d = scip::decodeScan(out[0], 3);
    CHECK_FALSE(d.scan);
    CHECK_THAT(d.error, Catch::Contains("checksum"));
  }
  SECTION("a lost data line leaves values that do not add up") {
    // Drop the second data line and its checksum: the checksums all pass, the count does not.
    std::string bad = good;
    std::size_t at = 0;
    for (int k = 0; k < 4; ++k) at = bad.find('\n', at) + 1;
    bad.erase(at, bad.find('\n', at) + 1 - at);
    scip::ReplyParser parser;
    const auto out = parser.feed(bad);
    REQUIRE(out.size() == 1);
    const auto d = scip::decodeScan(out[0], 3);  // 600 - 64 characters: not whole values
    CHECK_FALSE(d.scan);
    CHECK_THAT(d.error, Catch::Contains("536 characters is not whole"));
  }
  SECTION("a reply cut short is not returned until it ends") {
    scip::ReplyParser parser;
    CHECK(parser.feed(good.substr(0, good.size() - 1)).empty());
    parser.reset();  // e.g. the device was reconnected
    CHECK(parser.feed("\n").empty());
  }
  SECTION("a refusal's status is named") {
    scip::ReplyParser parser;
    const auto out = parser.feed(scip::encodeScanReply("GD0000019900", "10", 0, {}, 3));
    REQUIRE(out.size() == 1);
    const auto d = scip::decodeScan(out[0], 3);
    CHECK_FALSE(d.scan);
    CHECK_THAT(d.error, Catch::Contains("status 10"));
  }
  SECTION("a bad status checksum, a missing status, an empty stream") {
    scip::ReplyParser parser;
    CHECK_THAT(parser.feed("GD0000019900\n00Q\n\n").at(0).error,
               Catch::Contains("status line '00Q': checksum mismatch"));
    CHECK_THAT(parser.feed("GD0000019900\n\n").at(0).error, Catch::Contains("no status line"));
    CHECK(parser.feed("").empty());
    CHECK(parser.feed("\n\n\n").empty());
  }
  SECTION("a timestamp that is not 4 characters") {
    scip::Reply r;
    r.echo = "GD0000019900";
    r.status = "00";
    r.payload = {"ab"};
    CHECK_THAT(scip::decodeScan(r, 3).error, Catch::Contains("timestamp"));
    CHECK_THAT(scip::decodeScan(r, 4).error, Catch::Contains("2 or 3"));
  }
}

}  // namespace scip_test
