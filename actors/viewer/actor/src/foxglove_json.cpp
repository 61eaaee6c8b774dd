// Tessera messages as Foxglove JSON: well-known schemas for scans, grids and poses, Cap'n
// Proto's JSON mapping for the rest.
#include <tessera/viewer/foxglove_json.hpp>

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/cloud.capnp.h>
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

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <vector>

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

enum class Kind {
  kLaserScan,
  kGrid,
  kPoseStamped,
  kGroundTruth,
  kOdometry,
  kPath,
  kPointCloud,
  kLocalPlan,
  kCameraFootprints,
  kSubmapPoses,
  kLandmarkMap,
  kLineMap,
  kGeneric
};

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
    add(Kind::kPointCloud, static_cast<msg::PointCloud*>(nullptr));
    add(Kind::kLocalPlan, static_cast<msg::LocalPlan*>(nullptr));
    add(Kind::kCameraFootprints, static_cast<msg::CameraFootprints*>(nullptr));
    const auto generic = Kind::kGeneric;
    add(generic, static_cast<msg::MarkerDetection*>(nullptr));
    add(generic, static_cast<msg::CameraEvent*>(nullptr));
    add(generic, static_cast<msg::CameraCalibration*>(nullptr));
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
    add(Kind::kLandmarkMap, static_cast<msg::LandmarkMap*>(nullptr));
    add(Kind::kLineMap, static_cast<msg::LineMap*>(nullptr));
    add(generic, static_cast<msg::NavGoal*>(nullptr));
    add(generic, static_cast<msg::NavStatus*>(nullptr));
    add(generic, static_cast<msg::WheelTicks*>(nullptr));
    add(generic, static_cast<msg::ImuSample*>(nullptr));
    add(generic, static_cast<msg::BaseStatus*>(nullptr));
    add(generic, static_cast<msg::Submap*>(nullptr));
    add(generic, static_cast<msg::SubmapConstraint*>(nullptr));
    add(Kind::kSubmapPoses, static_cast<msg::SubmapPoses*>(nullptr));
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

// foxglove.SceneUpdate: entities of line and text primitives (what Tessera draws with it).
const char* const kColor =
    R"({"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}})";
const char* const kPoint =
    R"({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}})";

std::string sceneUpdateSchema() {
  const std::string line =
      std::string(R"({"type":"object","properties":{"type":{"type":"integer"},"pose":)") + kPose +
      R"(,"thickness":{"type":"number"},"scale_invariant":{"type":"boolean"},)"
      R"("points":{"type":"array","items":)" +
      kPoint + R"(},"color":)" + kColor + R"(,"colors":{"type":"array","items":)" + kColor +
      R"(},"indices":{"type":"array","items":{"type":"integer"}}}})";
  const std::string text = std::string(R"({"type":"object","properties":{"pose":)") + kPose +
                           R"(,"billboard":{"type":"boolean"},"font_size":{"type":"number"},)"
                           R"("scale_invariant":{"type":"boolean"},"color":)" +
                           kColor + R"(,"text":{"type":"string"}}})";
  const std::string arrow =
      std::string(R"({"type":"object","properties":{"pose":)") + kPose +
      R"(,"shaft_length":{"type":"number"},"shaft_diameter":{"type":"number"},)"
      R"("head_length":{"type":"number"},"head_diameter":{"type":"number"},"color":)" +
      kColor + "}}";
  const std::string sphere = std::string(R"({"type":"object","properties":{"pose":)") + kPose +
                             R"(,"size":)" + kPoint + R"(,"color":)" + kColor + "}}";
  const std::string metadata =
      R"({"type":"array","items":{"type":"object","properties":{"key":{"type":"string"},"value":{"type":"string"}}}})";
  const std::string any = R"({"type":"array","items":{"type":"object"}})";
  const std::string entity =
      std::string(R"({"type":"object","properties":{"timestamp":)") + kTime +
      R"(,"frame_id":{"type":"string"},"id":{"type":"string"},"lifetime":)" + kTime +
      R"(,"frame_locked":{"type":"boolean"},"metadata":)" + metadata +
      R"(,"arrows":{"type":"array","items":)" + arrow + R"(},"cubes":)" + any +
      R"(,"spheres":{"type":"array","items":)" + sphere + R"(},"cylinders":)" + any +
      R"(,"lines":{"type":"array","items":)" + line + R"(},"triangles":)" + any +
      R"(,"texts":{"type":"array","items":)" + text + R"(},"models":)" + any + "}}";
  return objectSchema(
      "foxglove.SceneUpdate",
      std::string(
          R"("deletions":{"type":"array","items":{"type":"object","properties":{"timestamp":)") +
          kTime +
          R"(,"type":{"type":"integer"},"id":{"type":"string"}}}},"entities":{"type":"array","items":)" +
          entity + "}");
}

/// A SceneEntity with every primitive list present (Foxglove expects them all) but "lines",
/// which withLines() adds as text.
json sceneEntity(std::int64_t stamp_ns, const std::string& frame, const std::string& id) {
  return {{"timestamp", stamp(stamp_ns)},
          {"frame_id", frame},
          {"id", id},
          {"lifetime", {{"sec", 0}, {"nsec", 0}}},  // until replaced or deleted
          {"frame_locked", true},
          {"metadata", json::array()},
          {"arrows", json::array()},
          {"cubes", json::array()},
          {"spheres", json::array()},
          {"cylinders", json::array()},
          {"triangles", json::array()},
          {"texts", json::array()},
          {"models", json::array()}};
}

/// `entity` as JSON text with "lines": the given line primitives (JSON texts).
std::string withLines(const json& entity, const std::vector<std::string>& lines) {
  std::string out = entity.dump();
  out.pop_back();  // the closing brace
  out += R"(,"lines":[)";
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (i > 0) out += ',';
    out += lines[i];
  }
  out += "]}";
  return out;
}

/// The shortest text that reads back as `v` (JSON has no inf or NaN: callers skip those).
template <class T>
void appendNumber(std::string& out, T v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

/// A line primitive through flat (x, y) pairs at z = 0, `width_px` screen pixels wide, in
/// colour (r, g, b, a), as JSON text (written directly: a dynamic window's 231 arcs of 16 points
/// each, five times a second, cost nlohmann's objects several times more).
/// type: 0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST.
template <class List>
std::string linePrimitive(int type, const List& xy, double width_px,
                          const std::array<double, 4>& rgba) {
  std::string out =
      R"({"type":)" + std::to_string(type) +
      R"(,"pose":{"position":{"x":0,"y":0,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}})"
      R"(,"thickness":)";
  appendNumber(out, width_px);
  out += R"(,"scale_invariant":true,"points":[)";
  bool first = true;
  const auto n = xy.size() / 2;
  for (decltype(xy.size()) i = 0; i < n; ++i) {
    const auto x = xy[2 * i], y = xy[2 * i + 1];
    if (!std::isfinite(x) || !std::isfinite(y)) continue;
    out += first ? R"({"x":)" : R"(,{"x":)";
    first = false;
    appendNumber(out, x);
    out += R"(,"y":)";
    appendNumber(out, y);
    out += R"(,"z":0})";
  }
  out += R"(],"color":{"r":)";
  appendNumber(out, rgba[0]);
  out += R"(,"g":)";
  appendNumber(out, rgba[1]);
  out += R"(,"b":)";
  appendNumber(out, rgba[2]);
  out += R"(,"a":)";
  appendNumber(out, rgba[3]);
  out += R"(},"colors":[],"indices":[]})";
  return out;
}

json rgbaJson(const std::array<double, 4>& c) {
  return {{"r", c[0]}, {"g", c[1]}, {"b", c[2]}, {"a", c[3]}};
}

/// A text label at (x, y), size_px screen pixels high, facing the viewer.
json label(double x, double y, const std::string& text, double size_px,
           const std::array<double, 4>& rgba) {
  return {{"pose", planarPose(x, y, 0)}, {"billboard", true},       {"font_size", size_px},
          {"scale_invariant", true},     {"color", rgbaJson(rgba)}, {"text", text}};
}

/// {"deletions": ..., "entities": [...]} with the entities given as JSON texts.
std::string sceneUpdate(const json& deletions, const std::vector<std::string>& entities) {
  std::string out = R"({"deletions":)" + deletions.dump() + R"(,"entities":[)";
  for (std::size_t i = 0; i < entities.size(); ++i) {
    if (i > 0) out += ',';
    out += entities[i];
  }
  out += "]}";
  return out;
}

/// A LocalPlan as one entity "local_plan": inadmissible arcs faint red, admissible ones from
/// blue (low score) to yellow (high), the chosen one green and thick; an empty plan (the goal
/// ended) deletes the entity.
std::string localPlanScene(msg::LocalPlan::Reader m) {
  const std::int64_t t = m.getHeader().getStampNs();
  const std::string frame = m.getHeader().getFrameId().cStr();
  const auto arcs = m.getArcs();
  json deletions = json::array();
  std::vector<std::string> entities;
  if (arcs.size() == 0) {
    deletions.push_back({{"timestamp", stamp(t)}, {"type", 0}, {"id", "local_plan"}});
  } else {
    json e = sceneEntity(t, frame, "local_plan");
    float best = 0;
    for (const auto a : arcs)
      if (a.getAdmissible() && std::isfinite(a.getScore())) best = std::max(best, a.getScore());
    std::vector<std::string> lines;
    lines.reserve(arcs.size() + 1);
    for (const auto a : arcs) {
      if (!a.getAdmissible()) {
        lines.push_back(linePrimitive(0, a.getXy(), 1.0, {0.9, 0.25, 0.2, 0.35}));
      } else {
        const double s = best > 0 && std::isfinite(a.getScore()) ? a.getScore() / best : 0.0;
        lines.push_back(
            linePrimitive(0, a.getXy(), 1.5, {0.2 + 0.8 * s, 0.45 + 0.45 * s, 1.0 - s, 0.7}));
      }
    }
    const int chosen = m.getChosen();
    if (chosen >= 0 && static_cast<unsigned>(chosen) < arcs.size())
      lines.push_back(linePrimitive(0, arcs[static_cast<unsigned>(chosen)].getXy(), 4.0,
                                    {0.18, 0.75, 0.44, 1.0}));
    e["metadata"].push_back({{"key", "goal_id"}, {"value", std::to_string(m.getGoalId())}});
    e["metadata"].push_back({{"key", "command"},
                             {"value", std::to_string(m.getCommand().getVx()) + " m/s, " +
                                           std::to_string(m.getCommand().getOmega()) + " rad/s"}});
    entities.push_back(withLines(e, lines));
  }
  return sceneUpdate(deletions, entities);
}

/// CameraFootprints as one entity per camera, "camera_<id>": its floor polygon (orange when
/// known, green when calibrated) and a label at the polygon's centre.
std::string cameraFootprintsScene(msg::CameraFootprints::Reader m) {
  const std::int64_t t = m.getHeader().getStampNs();
  const std::string frame = m.getHeader().getFrameId().cStr();
  std::vector<std::string> entities;
  for (const auto c : m.getCameras()) {
    const auto xy = c.getXy();
    if (xy.size() % 2 != 0)
      throw MessageError("foxglove: camera " + std::to_string(c.getCameraId()) +
                         "'s footprint has an odd number of coordinates (" +
                         std::to_string(xy.size()) + ")");
    json e = sceneEntity(t, frame, "camera_" + std::to_string(c.getCameraId()));
    const std::array<double, 4> rgba =
        c.getCalibrated() ? std::array{0.18, 0.75, 0.44, 0.9} : std::array{1.0, 0.6, 0.1, 0.9};
    double cx = 0, cy = 0;
    int n = 0;
    for (unsigned i = 0; i + 1 < xy.size(); i += 2)
      if (std::isfinite(xy[i]) && std::isfinite(xy[i + 1])) cx += xy[i], cy += xy[i + 1], ++n;
    if (n > 0)
      e["texts"].push_back(
          label(cx / n, cy / n, "camera " + std::to_string(c.getCameraId()), 14.0, rgba));
    e["metadata"].push_back(
        {{"key", "calibrated"}, {"value", c.getCalibrated() ? "true" : "false"}});
    entities.push_back(withLines(e, {linePrimitive(1, xy, 2.0, rgba)}));
  }
  return sceneUpdate(json::array(), entities);
}

/// SubmapPoses as one entity per submap, "submap_<id>" (metadata submap_id): an arrow along
/// its frame's x axis and its id. The message lists every submap, so the update first deletes
/// all earlier entities.
std::string submapPosesScene(msg::SubmapPoses::Reader m) {
  const std::int64_t t = m.getHeader().getStampNs();
  const std::string frame = m.getHeader().getFrameId().cStr();
  const std::array<double, 4> purple{0.56, 0.36, 0.97, 1.0};
  std::vector<std::string> entities;
  for (const auto p : m.getPoses()) {
    const auto pose = p.getPose();
    if (!std::isfinite(pose.getX()) || !std::isfinite(pose.getY()) ||
        !std::isfinite(pose.getTheta()))
      continue;
    const std::string id = std::to_string(p.getId());
    json e = sceneEntity(t, frame, "submap_" + id);
    e["arrows"].push_back({{"pose", pose2d(pose)},
                           {"shaft_length", 0.35},
                           {"shaft_diameter", 0.04},
                           {"head_length", 0.15},
                           {"head_diameter", 0.12},
                           {"color", rgbaJson(purple)}});
    e["texts"].push_back(label(pose.getX(), pose.getY(), id, 11.0, purple));
    e["metadata"].push_back({{"key", "submap_id"}, {"value", id}});
    entities.push_back(withLines(e, {}));
  }
  return sceneUpdate(json::array({{{"timestamp", stamp(t)}, {"type", 1}, {"id", ""}}}), entities);
}

/// A LandmarkMap as one entity "landmarks": a 0.3 m sphere per landmark (its id in the
/// sphere's order in metadata "ids", comma-separated).
std::string landmarkMapScene(msg::LandmarkMap::Reader m) {
  const std::int64_t t = m.getHeader().getStampNs();
  json e = sceneEntity(t, m.getHeader().getFrameId().cStr(), "landmarks");
  std::string ids;
  for (const auto l : m.getLandmarks()) {
    if (!std::isfinite(l.getX()) || !std::isfinite(l.getY())) continue;
    e["spheres"].push_back({{"pose", planarPose(l.getX(), l.getY(), 0)},
                            {"size", {{"x", 0.3}, {"y", 0.3}, {"z", 0.3}}},
                            {"color", rgbaJson({0.9, 0.63, 0.0, 1.0})}});
    ids += (ids.empty() ? "" : ",") + std::to_string(l.getId());
  }
  e["metadata"].push_back({{"key", "ids"}, {"value", ids}});
  return sceneUpdate(json::array(), {withLines(e, {})});
}

/// A LineMap as one entity "lines": each line's extent as a segment of one line list.
std::string lineMapScene(msg::LineMap::Reader m) {
  const std::int64_t t = m.getHeader().getStampNs();
  json e = sceneEntity(t, m.getHeader().getFrameId().cStr(), "lines");
  std::vector<double> xy;
  for (const auto l : m.getLines()) {
    const double v[] = {l.getX0(), l.getY0(), l.getX1(), l.getY1()};
    if (std::all_of(std::begin(v), std::end(v), [](double d) { return std::isfinite(d); }))
      xy.insert(xy.end(), std::begin(v), std::end(v));
  }
  return sceneUpdate(json::array(),
                     {withLines(e, {linePrimitive(2, xy, 2.0, {0.75, 0.22, 0.17, 1.0})})});
}

/// A PointCloud as foxglove.PointCloud: x, y, z float32 (and red, green, blue uint8 when the
/// cloud has colour) packed per point.
std::string pointCloudJson(msg::PointCloud::Reader m) {
  const std::size_t n = m.getCount();
  const auto xyz = m.getXyz();
  const auto rgb = m.getRgb();
  if (xyz.size() != n * 12)
    throw MessageError("foxglove: PointCloud of " + std::to_string(n) + " points carries " +
                       std::to_string(xyz.size()) + " xyz bytes, expected " +
                       std::to_string(n * 12));
  if (rgb.size() != 0 && rgb.size() != n * 3)
    throw MessageError("foxglove: PointCloud of " + std::to_string(n) + " points carries " +
                       std::to_string(rgb.size()) + " rgb bytes, expected 0 or " +
                       std::to_string(n * 3));
  // Foxglove's NumericType: UINT8 = 1, FLOAT32 = 7.
  json fields = json::array({{{"name", "x"}, {"offset", 0}, {"type", 7}},
                             {{"name", "y"}, {"offset", 4}, {"type", 7}},
                             {{"name", "z"}, {"offset", 8}, {"type", 7}}});
  std::size_t stride = 12;
  std::string packed;
  if (rgb.size() == 0) {
    packed.assign(reinterpret_cast<const char*>(xyz.begin()), xyz.size());
  } else {
    stride = 16;
    fields.push_back({{"name", "red"}, {"offset", 12}, {"type", 1}});
    fields.push_back({{"name", "green"}, {"offset", 13}, {"type", 1}});
    fields.push_back({{"name", "blue"}, {"offset", 14}, {"type", 1}});
    packed.assign(n * stride, '\0');
    for (std::size_t i = 0; i < n; ++i) {
      std::memcpy(packed.data() + i * stride, xyz.begin() + i * 12, 12);
      std::memcpy(packed.data() + i * stride + 12, rgb.begin() + i * 3, 3);
      packed[i * stride + 15] = static_cast<char>(0xff);
    }
  }
  return json{
      {"timestamp", stamp(m.getHeader().getStampNs())},
      {"frame_id", m.getHeader().getFrameId().cStr()},
      {"pose", planarPose(0, 0, 0)},
      {"point_stride", stride},
      {"fields", std::move(fields)},
      {"data", kj::encodeBase64(
                   kj::arrayPtr(reinterpret_cast<const kj::byte*>(packed.data()), packed.size()))
                   .cStr()}}
      .dump();
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
    case Kind::kPointCloud:
      return {
          "foxglove.PointCloud", "jsonschema",
          objectSchema(
              "foxglove.PointCloud",
              timeFramePose() +
                  R"(,"point_stride":{"type":"integer"},)"
                  R"("fields":{"type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"offset":{"type":"integer"},"type":{"type":"integer"}}}},)"
                  R"("data":{"type":"string","contentEncoding":"base64"})")};
    case Kind::kLocalPlan:
    case Kind::kCameraFootprints:
    case Kind::kSubmapPoses:
    case Kind::kLandmarkMap:
    case Kind::kLineMap:
      return {"foxglove.SceneUpdate", "jsonschema", sceneUpdateSchema()};
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
      case Kind::kPointCloud:
        return pointCloudJson(root.getAs<msg::PointCloud>());
      case Kind::kLocalPlan:
        return localPlanScene(root.getAs<msg::LocalPlan>());
      case Kind::kCameraFootprints:
        return cameraFootprintsScene(root.getAs<msg::CameraFootprints>());
      case Kind::kSubmapPoses:
        return submapPosesScene(root.getAs<msg::SubmapPoses>());
      case Kind::kLandmarkMap:
        return landmarkMapScene(root.getAs<msg::LandmarkMap>());
      case Kind::kLineMap:
        return lineMapScene(root.getAs<msg::LineMap>());
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
