// CloudMap: per-keyframe clouds at their current poses, the assembled global cloud and its PCD /
// PLY files (pcl::io, binary, in libtessera_pcl_bridge.so, loaded on first use: pcl_bridge.hpp).
#include "pcl_bridge.hpp"

#include <tessera/io/atomic_file.hpp>
#include <tessera/mapping3d/cloud_map.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>

namespace tessera::mapping3d {

void CloudMapOptions::validate() const {
  if (!std::isfinite(voxel_leaf) || voxel_leaf < 0)
    throw std::invalid_argument("voxel_leaf must be finite and >= 0");
}

void checkPose(const Eigen::Isometry3d& pose, const char* field) {
  if (!pose.matrix().allFinite()) throw std::invalid_argument(std::string(field) + ": not finite");
  const Eigen::Matrix3d r = pose.linear();
  if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
      r.determinant() <= 0)
    throw std::invalid_argument(std::string(field) + ": rotation is not orthonormal");
}

CloudMap::CloudMap(const CloudMapOptions& options) : options_(options) {
  options_.validate();
}

void CloudMap::setKeyframe(std::uint64_t id, PointCloud cloud,
                           const Eigen::Isometry3d& camera_to_world) {
  checkPose(camera_to_world, "pose");
  if (cloud.hasColor() && cloud.colors.size() != cloud.points.size())
    throw std::invalid_argument("cloud: " + std::to_string(cloud.colors.size()) + " colours for " +
                                std::to_string(cloud.points.size()) + " points");
  keyframes_[id] = {std::make_shared<const PointCloud>(std::move(cloud)), camera_to_world};
}

void CloudMap::setPose(std::uint64_t id, const Eigen::Isometry3d& camera_to_world) {
  checkPose(camera_to_world, "pose");
  auto it = keyframes_.find(id);
  if (it == keyframes_.end())
    throw std::out_of_range("keyframe " + std::to_string(id) + " is not in the cloud map");
  it->second.camera_to_world = camera_to_world;
}

std::vector<std::uint64_t> CloudMap::ids() const {
  std::vector<std::uint64_t> out;
  out.reserve(keyframes_.size());
  for (const auto& [id, placed] : keyframes_) out.push_back(id);
  return out;
}

std::size_t CloudMap::pointCount() const {
  std::size_t n = 0;
  for (const auto& [id, k] : keyframes_) n += k.cloud->size();
  return n;
}

const PlacedCloud& CloudMap::keyframe(std::uint64_t id) const {
  auto it = keyframes_.find(id);
  if (it == keyframes_.end())
    throw std::out_of_range("keyframe " + std::to_string(id) + " is not in the cloud map");
  return it->second;
}

std::vector<PlacedCloud> CloudMap::snapshot() const {
  std::vector<PlacedCloud> out;
  out.reserve(keyframes_.size());
  for (const auto& [id, k] : keyframes_) out.push_back(k);
  return out;
}

PointCloud CloudMap::assemble() const {
  // Colour is kept only when every keyframe has it: a cloud of mixed points has none.
  const bool color =
      !keyframes_.empty() && std::all_of(keyframes_.begin(), keyframes_.end(), [](const auto& k) {
        return k.second.cloud->hasColor() || k.second.cloud->empty();
      });
  PointCloud all;
  all.points.reserve(pointCount());
  for (const auto& [id, k] : keyframes_) {
    const Eigen::Isometry3f t = k.camera_to_world.cast<float>();
    for (const auto& p : k.cloud->points) all.points.push_back(t * p);
    if (color) all.colors.insert(all.colors.end(), k.cloud->colors.begin(), k.cloud->colors.end());
  }
  return voxelFilter(all, options_.voxel_leaf);
}

void CloudMap::writePcd(const std::filesystem::path& file) const {
  mapping3d::writePcd(assemble(), file);
}

void CloudMap::writePly(const std::filesystem::path& file) const {
  mapping3d::writePly(assemble(), file);
}

namespace {

// pcl::io returns a negative code (and prints to stderr) on failure: turn that into an error that
// names the file.
void checkIo(int code, const std::filesystem::path& file, const char* what) {
  if (code < 0) throw std::runtime_error(file.string() + ": " + what + " failed");
}

// PCL 1.13's PCDReader dereferences fields a malformed header never declared (it crashed on a
// text file in our tests), so the header is checked here first: FIELDS with x, y and z, POINTS
// and a DATA line of a known encoding. A truncated body is left to PCL, which checks the size.
void checkPcdHeader(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error(file.string() + ": cannot open");
  bool xyz = false, points = false;
  std::string line;
  for (int n = 0; n < 64 && std::getline(in, line); ++n) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key.empty() || key[0] == '#') continue;
    if (key == "FIELDS") {
      std::set<std::string> names{std::istream_iterator<std::string>(words), {}};
      xyz = names.count("x") && names.count("y") && names.count("z");
    } else if (key == "POINTS") {
      long long count = -1;
      points = static_cast<bool>(words >> count) && count >= 0;
    } else if (key == "DATA") {
      std::string encoding;
      words >> encoding;
      if (encoding != "ascii" && encoding != "binary" && encoding != "binary_compressed")
        throw std::runtime_error(file.string() + ": PCD header: unknown DATA '" + encoding + "'");
      if (!xyz) throw std::runtime_error(file.string() + ": PCD header: FIELDS lacks x y z");
      if (!points) throw std::runtime_error(file.string() + ": PCD header: no POINTS count");
      return;
    } else if (key != "VERSION" && key != "SIZE" && key != "TYPE" && key != "COUNT" &&
               key != "WIDTH" && key != "HEIGHT" && key != "VIEWPOINT") {
      throw std::runtime_error(file.string() + ": PCD header: unexpected '" + key + "'");
    }
  }
  throw std::runtime_error(file.string() + ": PCD header: no DATA line");
}

}  // namespace

void writePcd(const PointCloud& cloud, const std::filesystem::path& file) {
  if (cloud.empty()) throw std::runtime_error(file.string() + ": the cloud is empty");
  // PCL writes by name: to a temporary name (extension kept) renamed into place when complete.
  io::replaceFileAtomically(file, [&](const std::filesystem::path& temp) {
    checkIo(pcl_bridge::savePcdBinary(cloud, temp.string()), file, "writing PCD");
  });
}

void writePly(const PointCloud& cloud, const std::filesystem::path& file) {
  if (cloud.empty()) throw std::runtime_error(file.string() + ": the cloud is empty");
  // Binary, no camera element (CloudCompare and pcl_viewer need only the vertices).
  io::replaceFileAtomically(file, [&](const std::filesystem::path& temp) {
    checkIo(pcl_bridge::savePlyBinary(cloud, temp.string()), file, "writing PLY");
  });
}

PointCloud readPcd(const std::filesystem::path& file) {
  checkPcdHeader(file);
  PointCloud cloud;
  checkIo(pcl_bridge::loadPcd(file.string(), cloud), file, "reading PCD");
  return cloud;
}

PointCloud readPly(const std::filesystem::path& file) {
  PointCloud cloud;
  checkIo(pcl_bridge::loadPly(file.string(), cloud), file, "reading PLY");
  return cloud;
}

}  // namespace tessera::mapping3d
