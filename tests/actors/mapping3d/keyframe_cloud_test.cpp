// Keyframe clouds from synthetic depth images, the voxel filter, the cloud map under moved
// keyframes, PCD/PLY round trips and bad input, and the loading of the PCL bridge module they all
// go through (libtessera_pcl_bridge.so beside this binary).
#include <tessera/mapping3d/cloud_map.hpp>
#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <catch2/catch.hpp>

#include <fstream>

#include "../../../actors/mapping3d/src/pcl_bridge.hpp"
#include "../../shared_data.hpp"
#include "mapping3d_fixtures.hpp"

using Catch::Matchers::Contains;
using namespace tessera::mapping3d;
using tessera::test::mapping3d::smallCamera;
using tessera::test::mapping3d::wallFrame;

TEST_CASE("keyframe cloud back-projects every valid pixel in the camera frame", "[mapping3d]") {
  const auto camera = smallCamera();
  auto frame = wallFrame(camera, 2.0);
  frame.depth.at<std::uint16_t>(0, 0) = 0;     // no reading
  frame.depth.at<std::uint16_t>(0, 1) = 9000;  // beyond max_depth
  frame.depth.at<std::uint16_t>(0, 2) = 100;   // nearer than min_depth
  KeyframeCloudOptions options;
  options.stride = 1;
  options.voxel_leaf = 0;
  const auto cloud = makeKeyframeCloud(camera, frame, options);
  REQUIRE(cloud.size() == static_cast<std::size_t>(camera.width * camera.height - 3));
  CHECK_FALSE(cloud.hasColor());
  // Pixel (3, 0) is the first kept one: x = (3 - cx) z / fx, y = (0 - cy) z / fy.
  CHECK(cloud.points[0].x() == Approx((3 - camera.cx) * 2.0 / camera.fx));
  CHECK(cloud.points[0].y() == Approx(-camera.cy * 2.0 / camera.fy));
  CHECK(cloud.points[0].z() == Approx(2.0));

  options.stride = 2;
  CHECK(makeKeyframeCloud(camera, wallFrame(camera, 2.0), options).size() ==
        static_cast<std::size_t>(camera.width / 2 * camera.height / 2));

  SECTION("colour is carried per point, grey as R = G = B") {
    frame.image = cv::Mat(frame.depth.size(), CV_8UC3, cv::Scalar(10, 20, 30));
    const auto coloured = makeKeyframeCloud(camera, frame, options);
    REQUIRE(coloured.colors.size() == coloured.size());
    CHECK(coloured.colors[5] == std::array<std::uint8_t, 3>{10, 20, 30});
    frame.image = cv::Mat(frame.depth.size(), CV_8UC1, cv::Scalar(77));
    CHECK(makeKeyframeCloud(camera, frame, options).colors[0] ==
          std::array<std::uint8_t, 3>{77, 77, 77});
  }
}

TEST_CASE("voxel filter keeps one averaged point per occupied voxel", "[mapping3d]") {
  PointCloud cloud;
  // Two points in each of 10 x 10 voxels of 0.1 m, colours 0 and 100.
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j) {
      cloud.points.emplace_back(0.1f * i + 0.03f, 0.1f * j + 0.03f, 0.05f);
      cloud.points.emplace_back(0.1f * i + 0.07f, 0.1f * j + 0.07f, 0.05f);
      cloud.colors.push_back({0, 0, 0});
      cloud.colors.push_back({100, 100, 100});
    }
  const auto filtered = voxelFilter(cloud, 0.1);
  REQUIRE(filtered.size() == 100);
  REQUIRE(filtered.hasColor());
  for (std::size_t k = 0; k < filtered.size(); ++k) {
    const auto& p = filtered.points[k];
    CHECK(std::fmod(p.x() + 1e-4, 0.1) == Approx(0.05).margin(1e-3));
    CHECK(int{filtered.colors[k][0]} == Approx(50).margin(1));
  }
  CHECK(voxelFilter(cloud, 0.0).size() == cloud.size());
  CHECK(voxelFilter(cloud, 10.0).size() == 1);
  CHECK_THROWS_WITH(voxelFilter(cloud, std::nan("")), Contains("leaf"));
}

TEST_CASE("a moved keyframe moves only its own points", "[mapping3d]") {
  const auto camera = smallCamera();
  KeyframeCloudOptions options;
  options.voxel_leaf = 0;
  CloudMapOptions map_options;
  map_options.voxel_leaf = 0;
  CloudMap map(map_options);
  const Eigen::Isometry3d a = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d b = Eigen::Isometry3d::Identity();
  b.translation() = Eigen::Vector3d(5, 0, 0);
  map.setKeyframe(1, makeKeyframeCloud(camera, wallFrame(camera, 2.0), options), a);
  map.setKeyframe(2, makeKeyframeCloud(camera, wallFrame(camera, 3.0), options), b);
  REQUIRE(map.keyframeCount() == 2);
  const auto n = map.keyframe(1).cloud->size();
  REQUIRE(map.pointCount() == 2 * n);

  auto before = map.assemble();
  REQUIRE(before.size() == 2 * n);
  Eigen::Isometry3d moved = Eigen::Isometry3d::Identity();
  moved.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()).toRotationMatrix();
  moved.translation() = Eigen::Vector3d(0.5, -0.2, 1.0);
  map.setPose(1, moved);
  const auto after = map.assemble();
  REQUIRE(after.size() == before.size());
  const auto& local = map.keyframe(1).cloud->points;
  for (std::size_t i = 0; i < n; ++i) {
    // Keyframe 1 comes first (id order): its points are the camera-frame ones through `moved`.
    CHECK((after.points[i] - (moved.cast<float>() * local[i])).norm() < 1e-5f);
    CHECK((after.points[n + i] - before.points[n + i]).norm() == 0.0f);
  }
  CHECK_THROWS_AS(map.setPose(9, moved), std::out_of_range);

  SECTION("the global filter merges overlapping keyframes") {
    CloudMap merged;  // default leaf 2 cm
    merged.setKeyframe(1, makeKeyframeCloud(camera, wallFrame(camera, 2.0), options), a);
    const auto single = merged.assemble().size();
    merged.setKeyframe(2, makeKeyframeCloud(camera, wallFrame(camera, 2.0), options), a);
    CHECK(merged.assemble().size() == single);
    CHECK(merged.pointCount() == 2 * n);
  }
}

TEST_CASE("cloud map files round-trip through PCD and PLY", "[mapping3d]") {
  const auto dir = tessera::test::scratchDir("mapping3d_io");
  const auto camera = smallCamera();
  auto frame = wallFrame(camera, 2.0);
  frame.image = cv::Mat(frame.depth.size(), CV_8UC3, cv::Scalar(200, 100, 50));
  CloudMap map;
  map.setKeyframe(7, makeKeyframeCloud(camera, frame), Eigen::Isometry3d::Identity());
  const auto cloud = map.assemble();
  REQUIRE(cloud.size() > 100);

  map.writePcd(dir / "cloud.pcd");
  map.writePly(dir / "cloud.ply");
  for (const auto& back : {readPcd(dir / "cloud.pcd"), readPly(dir / "cloud.ply")}) {
    REQUIRE(back.size() == cloud.size());
    REQUIRE(back.hasColor());
    for (std::size_t i = 0; i < back.size(); i += 17) {
      CHECK((back.points[i] - cloud.points[i]).norm() < 1e-6f);
      CHECK(back.colors[i] == cloud.colors[i]);
    }
  }
  // The PCD header says binary, as CloudCompare and pcl_viewer read fastest.
  std::ifstream pcd(dir / "cloud.pcd");
  std::string line;
  bool binary = false;
  while (std::getline(pcd, line))
    if (line.rfind("DATA", 0) == 0) {
      binary = line == "DATA binary";
      break;
    }
  CHECK(binary);

  SECTION("without colour") {
    PointCloud two;
    two.points = {Eigen::Vector3f(1, 2, 3), Eigen::Vector3f(4, 5, 6)};
    writePcd(two, dir / "plain.pcd");
    const auto plain = readPcd(dir / "plain.pcd");
    REQUIRE(plain.size() == 2);
    CHECK_FALSE(plain.hasColor());
    CHECK(plain.points[1] == Eigen::Vector3f(4, 5, 6));
  }
  SECTION("bad files name the file") {
    std::ofstream(dir / "junk.pcd") << "not a point cloud\n";
    CHECK_THROWS_WITH(readPcd(dir / "junk.pcd"), Contains("junk.pcd"));
    std::ofstream(dir / "junk.ply") << "ply\nformat nonsense\n";
    CHECK_THROWS_WITH(readPly(dir / "junk.ply"), Contains("junk.ply"));
    std::ofstream(dir / "no_xyz.pcd") << "VERSION .7\nFIELDS a b\nPOINTS 1\nDATA ascii\n1 2\n";
    CHECK_THROWS_WITH(readPcd(dir / "no_xyz.pcd"), Contains("x y z"));
    // Truncated bodies: half of each file.
    for (const char* name : {"cloud.pcd", "cloud.ply"}) {
      const auto half = std::filesystem::file_size(dir / name) / 2;
      std::filesystem::copy_file(dir / name, dir / (std::string("cut_") + name));
      std::filesystem::resize_file(dir / (std::string("cut_") + name), half);
    }
    CHECK_THROWS_WITH(readPcd(dir / "cut_cloud.pcd"), Contains("cut_cloud.pcd"));
    CHECK_THROWS_WITH(readPly(dir / "cut_cloud.ply"), Contains("cut_cloud.ply"));
    CHECK_THROWS_WITH(readPly(dir / "missing.ply"), Contains("missing.ply"));
    CHECK_THROWS_WITH(CloudMap().writePcd(dir / "empty.pcd"), Contains("empty.pcd"));
    CHECK_THROWS_WITH(map.writePly(dir / "no_such_dir" / "x.ply"), Contains("x.ply"));
  }
}

TEST_CASE("keyframe cloud and cloud map reject bad input naming the field", "[mapping3d]") {
  const auto camera = smallCamera();
  auto frame = wallFrame(camera, 2.0);
  SECTION("empty depth") {
    frame.depth = cv::Mat();
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("depth"));
  }
  SECTION("wrong depth type") {
    frame.depth.convertTo(frame.depth, CV_32F);
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("depth"));
  }
  SECTION("depth size is not the camera's") {
    frame.depth = cv::Mat(10, 10, CV_16UC1, cv::Scalar(1000));
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("depth: size 10x10"));
  }
  SECTION("colour size is not the depth's") {
    frame.image = cv::Mat(10, 10, CV_8UC3);
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("image: size"));
  }
  SECTION("zero or NaN depth scale") {
    frame.depth_scale = 0;
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("depth_scale"));
    frame.depth_scale = std::nan("");
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame), Contains("depth_scale"));
  }
  SECTION("bad intrinsics and options") {
    auto bad = camera;
    bad.fx = 0;
    CHECK_THROWS_WITH(makeKeyframeCloud(bad, frame), Contains("fx"));
    KeyframeCloudOptions options;
    options.stride = 0;
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame, options), Contains("stride"));
    options = {};
    options.max_depth = 0.1;
    CHECK_THROWS_WITH(makeKeyframeCloud(camera, frame, options), Contains("max_depth"));
  }
  SECTION("no valid depth is an empty cloud, not an error") {
    frame.depth.setTo(0);
    CHECK(makeKeyframeCloud(camera, frame).empty());
  }
  SECTION("NaN or non-rigid pose, mismatched colours") {
    CloudMap map;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation().x() = std::nan("");
    CHECK_THROWS_WITH(map.setKeyframe(1, {}, pose), Contains("pose"));
    pose = Eigen::Isometry3d::Identity();
    pose.linear() *= 2.0;
    CHECK_THROWS_WITH(map.setKeyframe(1, {}, pose), Contains("pose"));
    PointCloud odd;
    odd.points = {Eigen::Vector3f(1, 2, 3)};
    odd.colors = {{1, 2, 3}, {4, 5, 6}};
    CHECK_THROWS_WITH(map.setKeyframe(1, odd, Eigen::Isometry3d::Identity()), Contains("cloud"));
    CHECK(map.keyframeCount() == 0);
  }
}

TEST_CASE("the PCL bridge loads beside the binary, or says which path it could not load",
          "[mapping3d]") {
  namespace bridge = tessera::mapping3d::pcl_bridge;
  namespace fs = std::filesystem;
  const auto dir = tessera::test::scratchDir("mapping3d_bridge");
  SECTION("a module that does not exist") {
    const auto missing = dir / "nowhere" / bridge::kModuleName;
    CHECK_THROWS_WITH(bridge::loadModule(missing),
                      Contains("point-cloud support: cannot load " + missing.string() + ": ") &&
                          Contains("No such file") && Contains("beside the tessera binary"));
  }
  SECTION("a file that is not a shared object") {
    std::ofstream(dir / "libjunk.so") << "not an ELF file\n";
    CHECK_THROWS_WITH(bridge::loadModule(dir / "libjunk.so"),
                      Contains("cannot load " + (dir / "libjunk.so").string()));
  }
  SECTION("the process's module is the one beside the executable") {
    const auto& module = bridge::module();
    const auto exe_dir = fs::weakly_canonical(fs::read_symlink("/proc/self/exe")).parent_path();
    CHECK(module.path == exe_dir / bridge::kModuleName);
    CHECK(bridge::candidatePaths().front() == module.path);
    CHECK(&bridge::module() == &module);  // loaded once
  }
}

TEST_CASE("a PCD round trip through the PCL bridge keeps every point and colour", "[mapping3d]") {
  namespace bridge = tessera::mapping3d::pcl_bridge;
  const auto dir = tessera::test::scratchDir("mapping3d_bridge_io");
  PointCloud cloud;
  for (int i = 0; i < 1000; ++i) {
    cloud.points.emplace_back(0.001f * i - 0.3f, -1e-7f * i, 123.456f + 0.25f * i);
    cloud.colors.push_back({static_cast<std::uint8_t>(i), static_cast<std::uint8_t>(255 - i % 256),
                            static_cast<std::uint8_t>(i * 7)});
  }
  writePcd(cloud, dir / "colour.pcd");
  const auto back = readPcd(dir / "colour.pcd");
  CHECK(back.points == cloud.points);
  CHECK(back.colors == cloud.colors);

  // The bridge's own calls: PCL's result code, and the cloud as the file has it.
  PointCloud plain;
  plain.points = cloud.points;
  CHECK(bridge::savePcdBinary(plain, (dir / "plain.pcd").string()) == 0);
  PointCloud plain_back;
  CHECK(bridge::loadPcd((dir / "plain.pcd").string(), plain_back) == 0);
  CHECK(plain_back.points == plain.points);
  CHECK_FALSE(plain_back.hasColor());
  CHECK(bridge::loadPcd((dir / "missing.pcd").string(), plain_back) < 0);
  CHECK(plain_back.points == plain.points);  // untouched by the failed read
}
