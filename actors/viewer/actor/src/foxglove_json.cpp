// Tessera messages as Foxglove JSON: well-known schemas for scans, grids and poses, Cap'n
// Proto's JSON mapping for the rest.
#include <tessera/viewer/foxglove_json.hpp>

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/common.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/msg/landmark.capnp.h>
#include <tessera/msg/lines.capnp.h>
#include <tessera/msg/map.capnp.h>
#include <tessera/msg/navigation.capnp.h>
#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>

#include <capnp/compat/json.h>
#include <kj/encoding.h>
#include <kj/exception.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <map>

namespace tessera::viewer {

namespace {

using nlohmann::json;

json stamp(std::int64_t ns) {
  const std::int64_t sec = ns >= 0 ? ns / 1'000'000'000 : -((-ns + 999'999'999) / 1'000'000'000);
  return {{"sec", sec}, {"nsec", ns - sec * 1'000'000'000}};
}

json planarPose(double x, double y, double theta) {
  return {{"position", {{"x", x}, {"y", y}, {"z", 0.0}}},
          {"orientation",
           {{"x", 0.0}, {"y", 0.0}, {"z", std::sin(theta / 2)}, {"w", std::cos(theta / 2)}}}};
}

json pose2d(msg::Pose2D::Reader p) {
  return planarPose(p.getX(), p.getY(), p.getTheta());
}

// JSON Schemas of the well-known Foxglove types, as far as Tessera fills them.
const char* const kTime =
    R"({"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}})";
const char* const kPose =
    R"({"type":"object","properties":{"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}})";

std::string objectSchema(const std::string& title, const std::string& properties) {
  return R"({"title":")" + title + R"(","type":"object","properties":{)" + properties + "}}";
}

std::string timeFramePose() {
  return std::string(R"("timestamp":)") + kTime + R"(,"frame_id":{"type":"string"},"pose":)" +
         kPose;
}

enum class Kind { kLaserScan, kGrid, kPoseStamped, kGroundTruth, kOdometry, kPath, kGeneric };

struct TypeEntry {
  Kind kind;
  capnp::StructSchema schema;
};

const std::map<std::uint64_t, TypeEntry>& types() {
  static const std::map<std::uint64_t, TypeEntry> table = [] {
    std::map<std::uint64_t, TypeEntry> t;
    auto add = [&t]<class T>(Kind kind, T*) {
      t.emplace(capnp::typeId<T>(), TypeEntry{kind, capnp::Schema::from<T>()});
    };
    add(Kind::kLaserScan, static_cast<msg::LaserScan*>(nullptr));
    add(Kind::kGrid, static_cast<msg::OccupancyGrid*>(nullptr));
    add(Kind::kPoseStamped, static_cast<msg::PoseStamped*>(nullptr));
    add(Kind::kGroundTruth, static_cast<msg::GroundTruthPose*>(nullptr));
    add(Kind::kOdometry, static_cast<msg::Odometry*>(nullptr));
    add(Kind::kPath, static_cast<msg::Path*>(nullptr));
    const auto generic = Kind::kGeneric;
    add(generic, static_cast<msg::MarkerDetection*>(nullptr));
    add(generic, static_cast<msg::CameraEvent*>(nullptr));
    add(generic, static_cast<msg::Twist*>(nullptr));
    add(generic, static_cast<msg::Blob*>(nullptr));
    add(generic, static_cast<msg::Image*>(nullptr));
    add(generic, static_cast<msg::CameraIntrinsics*>(nullptr));
    add(generic, static_cast<msg::GroundTruthPose3D*>(nullptr));
    add(generic, static_cast<msg::PoseStamped3D*>(nullptr));
    add(generic, static_cast<msg::RgbdFrame*>(nullptr));
    add(generic, static_cast<msg::Keyframe*>(nullptr));
    add(generic, static_cast<msg::KeyframePoses*>(nullptr));
    add(generic, static_cast<msg::KeyframeConstraint*>(nullptr));
    add(generic, static_cast<msg::LandmarkScan*>(nullptr));
    add(generic, static_cast<msg::DriveControl*>(nullptr));
    add(generic, static_cast<msg::LandmarkMap*>(nullptr));
    add(generic, static_cast<msg::LineMap*>(nullptr));
    add(generic, static_cast<msg::NavGoal*>(nullptr));
    add(generic, static_cast<msg::NavStatus*>(nullptr));
    add(generic, static_cast<msg::WheelTicks*>(nullptr));
    add(generic, static_cast<msg::ImuSample*>(nullptr));
    add(generic, static_cast<msg::Submap*>(nullptr));
    add(generic, static_cast<msg::SubmapConstraint*>(nullptr));
    add(generic, static_cast<msg::SubmapPoses*>(nullptr));
    return t;
  }();
  return table;
}

const TypeEntry& entry(std::uint64_t type_id) {
  const auto it = types().find(type_id);
  if (it == types().end()) {
    char hex[32];
    std::snprintf(hex, sizeof hex, "0x%016llx", static_cast<unsigned long long>(type_id));
    throw MessageError(std::string("foxglove: message type ") + hex + " is not a Tessera type");
  }
  return it->second;
}

/// Data fields as base64 strings (the JSON mapping's default, a list of numbers, would make an
/// image several times its size).
class Base64Data final : public capnp::JsonCodec::Handler<capnp::Data> {
 public:
  void encode(const capnp::JsonCodec& /*codec*/, capnp::Data::Reader input,
              capnp::JsonValue::Builder output) const override {
    output.setString(kj::encodeBase64(input));
  }
  capnp::Orphan<capnp::Data> decode(const capnp::JsonCodec& /*codec*/,
                                    capnp::JsonValue::Reader /*input*/,
                                    capnp::Orphanage /*orphanage*/) const override {
    KJ_FAIL_REQUIRE("tessera exports JSON only");
  }
};

/// foxglove.PoseInFrame of any message with a header and a planar pose.
template <class Reader>
std::string poseInFrame(Reader m) {
  return json{{"timestamp", stamp(m.getHeader().getStampNs())},
              {"frame_id", m.getHeader().getFrameId().cStr()},
              {"pose", pose2d(m.getPose())}}
      .dump();
}

double finiteOrZero(float v) {
  return std::isfinite(v) ? static_cast<double>(v) : 0.0;
}

}  // namespace

bool knownMessageType(std::uint64_t type_id) {
  return types().count(type_id) > 0;
}

FoxgloveSchema frameTransformSchema() {
  return {
      "foxglove.FrameTransform", "jsonschema",
      objectSchema(
          "foxglove.FrameTransform",
          std::string(R"("timestamp":)") + kTime +
              R"(,"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},)"
              R"("translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},)"
              R"("rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}})")};
}

std::string frameTransformJson(std::int64_t stamp_ns, const std::string& parent,
                               const std::string& child, double x, double y, double theta) {
  const json pose = planarPose(x, y, theta);
  return json{{"timestamp", stamp(stamp_ns)},
              {"parent_frame_id", parent},
              {"child_frame_id", child},
              {"translation", pose["position"]},
              {"rotation", pose["orientation"]}}
      .dump();
}

FoxgloveSchema foxgloveSchemaFor(std::uint64_t type_id) {
  switch (entry(type_id).kind) {
    case Kind::kLaserScan:
      return {"foxglove.LaserScan", "jsonschema",
              objectSchema("foxglove.LaserScan",
                           timeFramePose() +
                               R"(,"start_angle":{"type":"number"},"end_angle":{"type":"number"},)"
                               R"("ranges":{"type":"array","items":{"type":"number"}},)"
                               R"("intensities":{"type":"array","items":{"type":"number"}})")};
    case Kind::kGrid:
      return {
          "foxglove.Grid", "jsonschema",
          objectSchema(
              "foxglove.Grid",
              timeFramePose() +
                  R"(,"column_count":{"type":"integer"},"cell_size":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"}}},)"
                  R"("row_stride":{"type":"integer"},"cell_stride":{"type":"integer"},)"
                  R"("fields":{"type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"offset":{"type":"integer"},"type":{"type":"integer"}}}},)"
                  R"("data":{"type":"string","contentEncoding":"base64"})")};
    case Kind::kPoseStamped:
    case Kind::kGroundTruth:
    case Kind::kOdometry:
      return {"foxglove.PoseInFrame", "jsonschema",
              objectSchema("foxglove.PoseInFrame", timeFramePose())};
    case Kind::kPath:
      return {"foxglove.PosesInFrame", "jsonschema",
              objectSchema("foxglove.PosesInFrame",
                           std::string(R"("timestamp":)") + kTime +
                               R"(,"frame_id":{"type":"string"},"poses":{"type":"array","items":)" +
                               kPose + "}")};
    case Kind::kGeneric:
      break;
  }
  return {};
}

std::string foxgloveJson(std::uint64_t type_id, const MessageStorage& message) {
  const TypeEntry& e = entry(type_id);
  try {
    const capnp::AnyPointer::Reader root = message.root();
    switch (e.kind) {
      case Kind::kLaserScan: {
        const auto m = root.getAs<msg::LaserScan>();
        const auto r = m.getRanges();
        json ranges = json::array(), intensities = json::array();
        for (const float v : r) ranges.push_back(finiteOrZero(v));
        for (const float v : m.getIntensities()) intensities.push_back(finiteOrZero(v));
        const double n = r.size() > 0 ? static_cast<double>(r.size() - 1) : 0.0;
        return json{{"timestamp", stamp(m.getHeader().getStampNs())},
                    {"frame_id", m.getHeader().getFrameId().cStr()},
                    // The scan's own frame: its mount on base_link is a transform (tf).
                    {"pose", planarPose(0, 0, 0)},
                    {"start_angle", m.getAngleMin()},
                    {"end_angle", m.getAngleMin() + m.getAngleIncrement() * n},
                    {"ranges", std::move(ranges)},
                    {"intensities", std::move(intensities)}}
            .dump();
      }
      case Kind::kGrid: {
        const auto m = root.getAs<msg::OccupancyGrid>();
        const auto cells = m.getCells();
        if (cells.size() != static_cast<std::size_t>(m.getWidth()) * m.getHeight())
          throw MessageError("foxglove: OccupancyGrid holds " + std::to_string(cells.size()) +
                             " cells, its header says " + std::to_string(m.getWidth()) + "x" +
                             std::to_string(m.getHeight()));
        const double res = m.getResolution();
        return json{{"timestamp", stamp(m.getHeader().getStampNs())},
                    {"frame_id", m.getHeader().getFrameId().cStr()},
                    {"pose", pose2d(m.getOrigin())},
                    {"column_count", m.getWidth()},
                    {"cell_size", {{"x", res}, {"y", res}}},
                    {"row_stride", m.getWidth()},
                    {"cell_stride", 1},
                    // Foxglove's NumericType INT8 = 2.
                    {"fields", json::array({{{"name", "occupancy"}, {"offset", 0}, {"type", 2}}})},
                    {"data", kj::encodeBase64(cells).cStr()}}
            .dump();
      }
      case Kind::kPoseStamped:
        return poseInFrame(root.getAs<msg::PoseStamped>());
      case Kind::kGroundTruth:
        return poseInFrame(root.getAs<msg::GroundTruthPose>());
      case Kind::kOdometry:
        return poseInFrame(root.getAs<msg::Odometry>());
      case Kind::kPath: {
        const auto m = root.getAs<msg::Path>();
        json poses = json::array();
        for (const auto p : m.getPoses()) poses.push_back(pose2d(p.getPose()));
        return json{{"timestamp", stamp(m.getHeader().getStampNs())},
                    {"frame_id", m.getHeader().getFrameId().cStr()},
                    {"poses", std::move(poses)}}
            .dump();
      }
      case Kind::kGeneric: {
        capnp::JsonCodec codec;
        Base64Data base64;
        codec.addTypeHandler(base64);
        return codec.encode(root.getAs<capnp::DynamicStruct>(e.schema)).cStr();
      }
    }
  } catch (const kj::Exception& ex) {
    throw MessageError(std::string("foxglove: cannot read a ") +
                       e.schema.getShortDisplayName().cStr() + ": " + ex.getDescription().cStr());
  }
  return {};
}

FrameSource frameSourceFor(const std::string& topic, std::uint64_t type_id) {
  if (type_id == messageTypeOf<msg::Odometry>().id) return FrameSource::kOdometry;
  if (type_id == messageTypeOf<msg::LaserScan>().id) return FrameSource::kScanMount;
  const std::string suffix = "map_to_odom";
  if (type_id == messageTypeOf<msg::PoseStamped>().id && topic.size() >= suffix.size() &&
      topic.compare(topic.size() - suffix.size(), suffix.size(), suffix) == 0)
    return FrameSource::kMapToOdom;
  return FrameSource::kNone;
}

std::optional<std::string> frameTransformFor(FrameSource source, const MessageStorage& message) {
  std::int64_t stamp = 0;
  std::string parent, child;
  double x = 0, y = 0, theta = 0;
  try {
    const capnp::AnyPointer::Reader root = message.root();
    switch (source) {
      case FrameSource::kOdometry: {
        const auto m = root.getAs<msg::Odometry>();
        stamp = m.getHeader().getStampNs();
        parent = m.getHeader().getFrameId().cStr();
        child = m.getChildFrameId().cStr();
        if (child.empty()) child = "base_link";
        x = m.getPose().getX(), y = m.getPose().getY(), theta = m.getPose().getTheta();
        break;
      }
      case FrameSource::kScanMount: {
        const auto m = root.getAs<msg::LaserScan>();
        stamp = m.getHeader().getStampNs();
        parent = "base_link";
        child = m.getHeader().getFrameId().cStr();
        x = m.getMountX(), y = m.getMountY(), theta = m.getMountTheta();
        break;
      }
      case FrameSource::kMapToOdom: {
        const auto m = root.getAs<msg::PoseStamped>();
        stamp = m.getHeader().getStampNs();
        parent = m.getHeader().getFrameId().cStr();
        child = "odom";
        x = m.getPose().getX(), y = m.getPose().getY(), theta = m.getPose().getTheta();
        break;
      }
      case FrameSource::kNone:
        return std::nullopt;
    }
  } catch (const kj::Exception& e) {
    throw MessageError(std::string("foxglove: frames: ") + e.getDescription().cStr());
  }
  // A transform needs two distinct named frames and a finite pose.
  if (parent.empty() || child.empty() || parent == child || !std::isfinite(x) ||
      !std::isfinite(y) || !std::isfinite(theta))
    return std::nullopt;
  return frameTransformJson(stamp, parent, child, x, y, theta);
}

}  // namespace tessera::viewer
