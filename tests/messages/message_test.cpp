#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/message.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

using namespace tessera;

namespace {
Message<msg::LaserScan> makeScan(std::size_t beams) {
  return makeMessage<msg::LaserScan>([&](msg::LaserScan::Builder b) {
    setHeader(b.initHeader(), 42, "laser", 7);
    b.setAngleMin(-1.5f);
    b.setAngleIncrement(0.01f);
    b.setRangeMax(30.f);
    auto r = mutableView<float>(b.initRanges(static_cast<unsigned>(beams)));
    for (std::size_t i = 0; i < beams; ++i) r[i] = 0.5f + static_cast<float>(i);
  });
}
}  // namespace

TEST_CASE("a message survives encode and decode with every field intact", "[messages]") {
  auto scan = makeScan(181);
  auto bytes = encodeMessage(*scan.storage());
  auto decoded = checkedMessage<msg::LaserScan>(decodeMessage(bytes, "test bytes"), "test bytes");
  CHECK(decoded->getHeader().getStampNs() == 42);
  CHECK(std::string(decoded->getHeader().getFrameId().cStr()) == "laser");
  CHECK(decoded->getHeader().getSeq() == 7);
  auto r = view<float>(decoded->getRanges());
  REQUIRE(r.size() == 181);
  CHECK(r[0] == 0.5f);
  CHECK(r[180] == 180.5f);
  CHECK(messageTypeOf<msg::LaserScan>().name == std::string("LaserScan"));
}

TEST_CASE("views point into the message bytes instead of copying them", "[messages]") {
  auto scan = makeScan(1000);
  auto r = view<float>(scan->getRanges());
  auto e = eigenView(scan->getRanges());
  const auto* p = reinterpret_cast<const capnp::word*>(r.data());
  bool inside = false;
  for (auto seg : scan.storage()->segments()) {
    inside = inside || (p >= seg.begin() && p + r.size_bytes() / sizeof(capnp::word) <= seg.end());
  }
  CHECK(inside);
  CHECK(static_cast<const void*>(e.data()) == static_cast<const void*>(r.data()));
  CHECK(e.sum() == Approx(1000 * 0.5 + 999.0 * 1000 / 2));
}

TEST_CASE("grid cells are exposed as int8 without copying", "[messages]") {
  auto grid = makeMessage<msg::OccupancyGrid>([](msg::OccupancyGrid::Builder b) {
    b.setWidth(3);
    b.setHeight(2);
    auto cells = mutableViewInt8(b.initCells(6));
    cells[0] = -1;
    cells[5] = 100;
  });
  auto cells = viewInt8(grid->getCells());
  REQUIRE(cells.size() == 6);
  CHECK(cells[0] == -1);
  CHECK(cells[5] == 100);
}

TEST_CASE("malformed bytes give a MessageError naming the source, never a crash", "[messages]") {
  SECTION("empty") {
    CHECK_THROWS_WITH(decodeMessage({}, "scan.bin"),
                      Catch::Contains("scan.bin") && Catch::Contains("empty"));
  }
  SECTION("not whole words") {
    std::vector<std::byte> b(13);
    CHECK_THROWS_WITH(decodeMessage(b, "scan.bin"), Catch::Contains("8-byte words"));
  }
  SECTION("truncated") {
    auto bytes = encodeMessage(*makeScan(500).storage());
    bytes.resize(bytes.size() / 2 / 8 * 8);
    CHECK_THROWS_AS(decodeMessage(bytes, "half"), MessageError);
  }
  SECTION("over the size limit") {
    auto bytes = encodeMessage(*makeScan(500).storage());
    DecodeLimits limits;
    limits.max_bytes = 100;
    CHECK_THROWS_WITH(decodeMessage(bytes, "big", limits), Catch::Contains("limit"));
  }
  SECTION("random garbage") {
    std::mt19937 rng(3);
    int rejected = 0;
    for (int trial = 0; trial < 500; ++trial) {
      std::vector<std::byte> b(8 * (1 + rng() % 64));
      for (auto& x : b) x = static_cast<std::byte>(rng());
      try {
        auto s = decodeMessage(b, "garbage");
        (void)checkedMessage<msg::LaserScan>(s, "garbage");
      } catch (const MessageError&) {
        ++rejected;
      }
    }
    CHECK(rejected > 400);  // the rest happen to be valid (tiny) messages; none may crash
  }
  SECTION("flipped bytes in a real message") {
    const auto good = encodeMessage(*makeScan(50).storage());
    std::mt19937 rng(5);
    for (int trial = 0; trial < 300; ++trial) {
      auto b = good;
      for (int k = 0; k < 4; ++k) b[rng() % b.size()] = static_cast<std::byte>(rng());
      try {
        auto m = checkedMessage<msg::LaserScan>(decodeMessage(b, "mutated"), "mutated");
        auto r = view<float>(m->getRanges());
        volatile float sink = 0;
        for (float v : r) sink = sink + v;  // reading every element must stay in bounds
      } catch (const MessageError&) {
      }
    }
    SUCCEED();
  }
}

TEST_CASE("large messages recycle their first segment and always start zeroed", "[messages]") {
  constexpr std::size_t kBytes = 200'000;
  const void* first_address = nullptr;
  {
    auto m = tessera::makeMessage<tessera::msg::Blob>(
        [&](tessera::msg::Blob::Builder b) {
          auto bytes = b.initPayload(kBytes);
          std::memset(bytes.begin(), 0xff, bytes.size());
        },
        kBytes + 64);
    first_address = m.storage()->address();
  }
  // The same size class comes back from the pool: the builder must have re-zeroed what it used,
  // or the new message would read the old bytes as its (default) fields.
  tessera::Loan<tessera::msg::Blob> again(kBytes + 64);
  CHECK(again->getHeader().getSeq() == 0);
  auto bytes = again->initPayload(kBytes);
  CHECK(std::all_of(bytes.begin(), bytes.end(), [](capnp::byte c) { return c == 0; }));
  auto sealed = std::move(again).seal();
  CHECK(sealed->address() == first_address);
}

TEST_CASE("a blob loaned beside the message is written once and read back through the field",
          "[messages]") {
  constexpr std::size_t kBytes = 100003;  // not whole words: the last one is padded
  Loan<msg::Blob> loan(std::size_t{0}, kBytes);
  REQUIRE(loan.blob().size() == kBytes);
  REQUIRE(reinterpret_cast<std::uintptr_t>(loan.blob().data()) % sizeof(capnp::word) == 0);
  setHeader(loan->initHeader(), 5, "camera", 9);
  for (std::size_t i = 0; i < kBytes; ++i) loan.blob()[i] = static_cast<std::byte>(i * 7 + 1);
  loan->adoptPayload(loan.blobData());
  CHECK_THROWS_AS(loan.blobData(), std::logic_error);  // one field per blob
  const Message<msg::Blob> m(std::move(loan).seal());

  // Read in place: the field's bytes are the blob's, not a copy.
  const auto payload = m->getPayload();
  REQUIRE(payload.size() == kBytes);
  bool same = true;
  for (std::size_t i = 0; i < kBytes; ++i)
    same = same && payload[i] == static_cast<kj::byte>(static_cast<std::byte>(i * 7 + 1));
  CHECK(same);
  CHECK(m->getHeader().getFrameId() == "camera");

  // Encoded with the blob as a segment of its own; the padding past the blob is zero.
  const auto bytes = encodeMessage(*m.storage());
  const auto decoded = checkedMessage<msg::Blob>(decodeMessage(bytes, "blob bytes"), "blob bytes");
  REQUIRE(decoded->getPayload().size() == kBytes);
  CHECK(std::equal(payload.begin(), payload.end(), decoded->getPayload().begin()));
  const auto segments = m.storage()->segments();
  REQUIRE(segments.size() == 2);
  const auto* pad = reinterpret_cast<const std::uint8_t*>(segments[1].end()) - 5;
  CHECK(std::all_of(pad, pad + 5, [](std::uint8_t b) { return b == 0; }));
}

TEST_CASE("a loan without a blob has none to attach", "[messages]") {
  Loan<msg::Blob> loan;
  CHECK(loan.blob().empty());
  CHECK_THROWS_AS(loan.blobData(), std::logic_error);
}

TEST_CASE("navigation goals and status survive encode and decode", "[messages]") {
  auto goal = makeMessage<msg::NavGoal>([](msg::NavGoal::Builder b) {
    setHeader(b.initHeader(), 5, "map", 0);
    writePose(b.initPose(), Pose2(3.0, -2.0, 1.5));
    b.setId(17);
    b.setToleranceXy(0.1);
    b.setToleranceYaw(std::numeric_limits<double>::infinity());
  });
  auto g =
      checkedMessage<msg::NavGoal>(decodeMessage(encodeMessage(*goal.storage()), "goal"), "goal");
  CHECK(g->getId() == 17);
  CHECK(toPose2(g->getPose()).x == 3.0);
  CHECK(std::isinf(g->getToleranceYaw()));
  CHECK(messageTypeOf<msg::NavGoal>().name == std::string("NavGoal"));

  auto status = makeMessage<msg::NavStatus>([](msg::NavStatus::Builder b) {
    setHeader(b.initHeader(), 6, "map", 0);
    b.setGoalId(17);
    b.setState(msg::NavStatus::State::REFUSED);
    b.setReason("goal inside an obstacle");
    b.setDistanceRemaining(std::nan(""));
  });
  auto s = checkedMessage<msg::NavStatus>(decodeMessage(encodeMessage(*status.storage()), "status"),
                                          "status");
  CHECK(s->getState() == msg::NavStatus::State::REFUSED);
  CHECK(std::string(s->getReason().cStr()) == "goal inside an obstacle");
  CHECK(std::isnan(s->getDistanceRemaining()));
}
