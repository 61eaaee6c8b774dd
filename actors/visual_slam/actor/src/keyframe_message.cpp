// Keyframe messages: writing from the tracker's keyframes and checking what arrives.
#include <tessera/visual_slam/keyframe_message.hpp>

#include <tessera/messages/geometry.hpp>

#include <cmath>
#include <cstring>

namespace tessera::visual_slam {
namespace {

std::size_t samples(int size, int step) {
  return static_cast<std::size_t>((size + step - 1) / step);
}

}  // namespace

std::size_t keyframeSizeHint(const KeyframeContent& k) {
  const Keyframe& kf = *k.keyframe;
  std::size_t bytes = 1024 + kf.keypoints.size() * (32 + 24);
  bytes += kf.descriptors.total() * kf.descriptors.elemSize();
  if (!k.depth.empty() && k.depth_step > 0)
    bytes += 2 * samples(k.depth.cols, k.depth_step) * samples(k.depth.rows, k.depth_step) + 8;
  return bytes;
}

void writeKeyframe(msg::Keyframe::Builder b, const KeyframeContent& k) {
  const Keyframe& kf = *k.keyframe;
  b.setId(static_cast<std::uint32_t>(kf.id));
  b.setFrameIndex(static_cast<std::uint32_t>(kf.frame));
  b.setDatasetTimeS(kf.timestamp);
  b.setTrackingInliers(static_cast<std::uint32_t>(std::max(0, k.tracking_inliers)));
  const Eigen::Isometry3d& T = kf.camera_to_world;
  writePose(b.initPose(), Pose3{T.translation(), Eigen::Quaterniond(T.rotation()).normalized()});
  auto in = b.initIntrinsics();
  in.setFx(k.camera.fx);
  in.setFy(k.camera.fy);
  in.setCx(k.camera.cx);
  in.setCy(k.camera.cy);
  in.setWidth(static_cast<std::uint32_t>(k.camera.width));
  in.setHeight(static_cast<std::uint32_t>(k.camera.height));

  const auto n = static_cast<unsigned>(kf.keypoints.size());
  auto kps = b.initKeypoints(n);
  auto pts = b.initPoints(n);
  for (unsigned i = 0; i < n; ++i) {
    const cv::KeyPoint& kp = kf.keypoints[i];
    kps[i].setU(kp.pt.x);
    kps[i].setV(kp.pt.y);
    kps[i].setSize(kp.size);
    kps[i].setAngle(kp.angle);
    kps[i].setOctave(kp.octave);
    kps[i].setResponse(kp.response);
    const bool valid = i < kf.points_camera.size() && kf.points_camera[i].allFinite();
    if (valid) {
      const Eigen::Vector3d& p = kf.points_camera[i];
      pts[i].setX(static_cast<float>(p.x()));
      pts[i].setY(static_cast<float>(p.y()));
      pts[i].setZ(static_cast<float>(p.z()));
    }
    pts[i].setValid(valid);
  }
  b.setDescriptorType(kf.descriptors.depth() == CV_32F ? "f32" : "u8");
  b.setDescriptorRows(static_cast<std::uint32_t>(kf.descriptors.rows));
  const std::size_t row_bytes = kf.descriptors.cols * kf.descriptors.elemSize();
  b.setDescriptorBytes(static_cast<std::uint32_t>(row_bytes));
  // Small fields first, then the bulk (descriptors, depth) at the end of the message.
  const bool has_depth = !k.depth.empty() && k.depth.type() == CV_16UC1 && k.depth_step > 0;
  const std::size_t dw = has_depth ? samples(k.depth.cols, k.depth_step) : 0;
  const std::size_t dh = has_depth ? samples(k.depth.rows, k.depth_step) : 0;
  b.setDepthStep(has_depth ? static_cast<std::uint32_t>(k.depth_step) : 0);
  b.setDepthWidth(static_cast<std::uint32_t>(dw));
  b.setDepthHeight(static_cast<std::uint32_t>(dh));
  b.setDepthScale(k.depth_scale);
  auto desc = b.initDescriptors(static_cast<unsigned>(row_bytes * kf.descriptors.rows));
  for (int r = 0; r < kf.descriptors.rows; ++r)
    std::memcpy(desc.begin() + r * row_bytes, kf.descriptors.ptr(r), row_bytes);
  if (has_depth) {
    auto depth = b.initDepth(static_cast<unsigned>(2 * dw * dh));
    std::uint8_t* out = depth.begin();
    for (std::size_t j = 0; j < dh; ++j) {
      const auto* row = k.depth.ptr<std::uint16_t>(static_cast<int>(j) * k.depth_step);
      for (std::size_t i = 0; i < dw; ++i) {
        const std::uint16_t v = row[i * static_cast<std::size_t>(k.depth_step)];
        *out++ = static_cast<std::uint8_t>(v & 0xff);  // little-endian, whatever the host
        *out++ = static_cast<std::uint8_t>(v >> 8);
      }
    }
  }
}

std::string keyframeMessageError(msg::Keyframe::Reader m) {
  const std::string id = "keyframe " + std::to_string(m.getId()) + ": ";
  const std::size_t n = m.getKeypoints().size();
  if (n == 0) return id + "no keypoints";
  if (m.getPoints().size() != n)
    return id + std::to_string(m.getPoints().size()) + " points for " + std::to_string(n) +
           " keypoints";
  if (m.getDescriptorRows() != n)
    return id + std::to_string(m.getDescriptorRows()) + " descriptor rows for " +
           std::to_string(n) + " keypoints";
  const std::string type = m.getDescriptorType().cStr();
  if (type != "u8" && type != "f32") return id + "descriptorType '" + type + "' (u8 | f32)";
  if (m.getDescriptorBytes() == 0 || (type == "f32" && m.getDescriptorBytes() % 4 != 0))
    return id + "descriptorBytes " + std::to_string(m.getDescriptorBytes());
  if (m.getDescriptors().size() != static_cast<std::size_t>(m.getDescriptorBytes()) * n)
    return id + "descriptors hold " + std::to_string(m.getDescriptors().size()) +
           " bytes, rows x descriptorBytes = " + std::to_string(m.getDescriptorBytes() * n);
  const auto p = m.getPose();
  const double pose[] = {p.getX(), p.getY(), p.getZ(), p.getQx(), p.getQy(), p.getQz(), p.getQw()};
  double qn = 0;
  for (int i = 0; i < 7; ++i) {
    if (!std::isfinite(pose[i])) return id + "pose is not finite";
    if (i >= 3) qn += pose[i] * pose[i];
  }
  if (qn < 1e-12) return id + "pose quaternion is zero";
  const auto in = m.getIntrinsics();
  if (!(std::isfinite(in.getFx()) && in.getFx() > 0 && std::isfinite(in.getFy()) &&
        in.getFy() > 0 && std::isfinite(in.getCx()) && std::isfinite(in.getCy())))
    return id + "bad intrinsics";
  for (const auto kp : m.getKeypoints())
    if (!std::isfinite(kp.getU()) || !std::isfinite(kp.getV())) return id + "keypoint not finite";
  for (const auto pt : m.getPoints())
    if (pt.getValid() &&
        !(std::isfinite(pt.getX()) && std::isfinite(pt.getY()) && std::isfinite(pt.getZ())))
      return id + "valid point not finite";
  const std::size_t depth_bytes = 2ull * m.getDepthWidth() * m.getDepthHeight();
  if (m.getDepth().size() != depth_bytes)
    return id + "depth holds " + std::to_string(m.getDepth().size()) + " bytes, " +
           std::to_string(depth_bytes) + " expected";
  if (depth_bytes > 0 && (m.getDepthStep() == 0 || !(m.getDepthScale() > 0)))
    return id + "depthStep or depthScale not positive";
  return "";
}

Pose3 keyframePose(msg::Keyframe::Reader m) {
  return toPose3(m.getPose());
}

}  // namespace tessera::visual_slam
