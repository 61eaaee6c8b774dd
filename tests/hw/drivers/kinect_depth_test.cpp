// The Kinect depth model (raw disparity <-> metres), the frame converter and the colour/depth
// pairing.
#include <tessera/drivers/kinect_depth.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <vector>

namespace kinect_depth_test {

using namespace tessera::drivers;

TEST_CASE("the Kinect depth model follows z = 8 b f / (offset - d) and inverts it",
          "[drivers][kinect]") {
  const KinectDepthModel m;
  // 8 * 0.075 * 580 = 348: d = 1000 is 348 / 90 m.
  REQUIRE(m.metres(1000).has_value());
  CHECK(*m.metres(1000) == Approx(348.0 / 90.0));
  for (const double z : {0.5, 1.0, 2.345, 4.0, 7.5}) {
    const int d = m.disparity(z);
    REQUIRE(m.metres(d).has_value());
    // One disparity step is z^2 / 348 m: rounding is within half of it.
    CHECK(std::abs(*m.metres(d) - z) <= 0.5 * z * z / 348.0 + 1e-9);
  }
  // Nearer depth means larger... smaller disparity: depth grows with d.
  CHECK(*m.metres(900) > *m.metres(800));
}

TEST_CASE("the Kinect depth model has no reading for 2047, out-of-range values or depths",
          "[drivers][kinect]") {
  const KinectDepthModel m;
  CHECK_FALSE(m.metres(KinectDepthModel::kNoReading));
  CHECK_FALSE(m.metres(-1));
  CHECK_FALSE(m.metres(5000));
  CHECK_FALSE(m.metres(1089));  // ~348 m: beyond max_depth_m
  CHECK_FALSE(m.metres(1500));  // beyond the offset: negative depth
  CHECK(m.disparity(std::numeric_limits<double>::quiet_NaN()) == KinectDepthModel::kNoReading);
  CHECK(m.disparity(0.1) == KinectDepthModel::kNoReading);
  CHECK(m.disparity(20.0) == KinectDepthModel::kNoReading);
  CHECK(m.disparity(-1.0) == KinectDepthModel::kNoReading);
}

TEST_CASE("an invalid Kinect depth model is refused naming the value", "[drivers][kinect]") {
  KinectDepthModel m;
  m.focal_px = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(m.validate(), Catch::Contains("focal_px"));
  m = {};
  m.max_depth_m = 0.3;
  CHECK_THROWS_WITH(m.validate(), Catch::Contains("max_depth_m"));
  m = {};
  m.disparity_offset = 4000;
  CHECK_THROWS_WITH(m.validate(), Catch::Contains("11-bit"));
  m = {};
  m.max_depth_m = 80;
  CHECK_THROWS_WITH(KinectDepthConverter(m, 1000), Catch::Contains("16 bits"));
}

TEST_CASE("the converter turns raw disparities into millimetres, 0 where there is none",
          "[drivers][kinect]") {
  const KinectDepthModel m;
  const KinectDepthConverter c(m, 1000);
  const std::vector<std::uint16_t> raw = {1000, 2047, 0, 600, 4095, 1500};
  std::vector<std::uint16_t> mm(raw.size());
  CHECK(c.convert(raw, mm) == 1);  // 4095: more than 11 bits, a corrupt transfer
  CHECK(mm[0] == static_cast<std::uint16_t>(std::lround(348.0 / 90.0 * 1000)));
  CHECK(mm[1] == 0);
  CHECK(mm[2] == 0);  // 0.319 m: inside the blind zone
  CHECK(mm[3] == static_cast<std::uint16_t>(std::lround(348.0 / 490.0 * 1000)));
  CHECK(mm[4] == 0);
  CHECK(mm[5] == 0);
  std::vector<std::uint16_t> short_out(2);
  CHECK_THROWS_AS(c.convert(raw, short_out), std::invalid_argument);
}

KinectImage at(std::int64_t ms) {
  KinectImage im;
  im.stamp_ns = ms * 1'000'000;
  im.bytes = {static_cast<std::uint8_t>(ms & 0xff)};
  return im;
}

TEST_CASE("colour and depth pair by arrival time; a frame without a partner is dropped",
          "[drivers][kinect]") {
  RgbdPairer p(20'000'000);
  CHECK_FALSE(p.addDepth(at(0)));
  auto pair = p.addColor(at(5));
  REQUIRE(pair);
  CHECK(pair->depth.stamp_ns == 0);
  CHECK(pair->color.stamp_ns == 5'000'000);
  // Colour first this time.
  CHECK_FALSE(p.addColor(at(33)));
  pair = p.addDepth(at(40));
  REQUIRE(pair);
  CHECK(pair->color.stamp_ns == 33'000'000);
  // A depth frame whose colour frame never came: replaced by the next one, then paired.
  CHECK_FALSE(p.addDepth(at(66)));
  CHECK_FALSE(p.addDepth(at(100)));
  pair = p.addColor(at(101));
  REQUIRE(pair);
  CHECK(pair->depth.stamp_ns == 100'000'000);
  // Too far apart: the older is dropped, the newer waits.
  CHECK_FALSE(p.addColor(at(133)));
  CHECK_FALSE(p.addDepth(at(200)));
  CHECK(p.paired() == 3);
  CHECK(p.dropped() == 2);
  p.reset();
  CHECK_FALSE(p.addColor(at(205)));  // the waiting depth frame was forgotten
}

}  // namespace kinect_depth_test
