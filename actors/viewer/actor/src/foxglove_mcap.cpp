// FoxgloveMcap: channels per topic, and the frame transforms odometry, scans and the
// localiser's map_to_odom imply, on one "tf" channel.
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>

#include <tessera/msg/common.capnp.h>
#include <tessera/msg/sensor.capnp.h>

#include <kj/exception.h>

#include <cmath>
#include <optional>

namespace tessera::viewer {

namespace {

struct Transform {
  std::int64_t stamp_ns = 0;
  std::string parent, child;
  double x = 0, y = 0, theta = 0;
};

}  // namespace

std::size_t FoxgloveMcap::addTopic(const std::string& topic, std::uint64_t type_id,
                                   const std::string& type_name) {
  if (!knownMessageType(type_id))
    throw MessageError("foxglove: topic '" + topic + "' has type " + type_name +
                       ", unknown to this build");
  Frames frames = Frames::kNone;
  if (type_id == messageTypeOf<msg::Odometry>().id) frames = Frames::kOdometry;
  if (type_id == messageTypeOf<msg::LaserScan>().id) frames = Frames::kScanMount;
  const std::string suffix = "map_to_odom";
  if (type_id == messageTypeOf<msg::PoseStamped>().id && topic.size() >= suffix.size() &&
      topic.compare(topic.size() - suffix.size(), suffix.size(), suffix) == 0)
    frames = Frames::kMapToOdom;
  // A schema per message type, added with its first topic.
  const FoxgloveSchema schema = foxgloveSchemaFor(type_id);
  std::uint16_t schema_id = 0;
  if (!schema.name.empty()) {
    auto [it, fresh] = schemas_.emplace(type_id, 0);
    if (fresh) it->second = writer_.addSchema(schema.name, schema.encoding, schema.data);
    schema_id = it->second;
  }
  topics_.push_back({type_id,
                     writer_.addChannel(schema_id, topic, "json", {{"tessera_type", type_name}}),
                     frames});
  return topics_.size() - 1;
}

std::uint16_t FoxgloveMcap::tfChannel() {
  if (tf_channel_ == 0) {
    const FoxgloveSchema transform = frameTransformSchema();
    const std::uint16_t schema =
        writer_.addSchema(transform.name, transform.encoding, transform.data);
    tf_channel_ = writer_.addChannel(schema, "tf", "json", {{"tessera_type", "(frames)"}});
  }
  return tf_channel_;
}

void FoxgloveMcap::write(std::size_t topic, std::uint64_t time_ns, const MessageStorage& message) {
  const Topic& t = topics_.at(topic);
  const std::string json = foxgloveJson(t.type_id, message);  // throws MessageError
  std::optional<Transform> tf;
  try {
    const capnp::AnyPointer::Reader root = message.root();
    switch (t.frames) {
      case Frames::kOdometry: {
        const auto m = root.getAs<msg::Odometry>();
        const std::string child = m.getChildFrameId().cStr();
        tf = Transform{m.getHeader().getStampNs(),
                       m.getHeader().getFrameId().cStr(),
                       child.empty() ? "base_link" : child,
                       m.getPose().getX(),
                       m.getPose().getY(),
                       m.getPose().getTheta()};
        break;
      }
      case Frames::kScanMount: {
        const auto m = root.getAs<msg::LaserScan>();
        tf = Transform{m.getHeader().getStampNs(),
                       "base_link",
                       m.getHeader().getFrameId().cStr(),
                       m.getMountX(),
                       m.getMountY(),
                       m.getMountTheta()};
        break;
      }
      case Frames::kMapToOdom: {
        const auto m = root.getAs<msg::PoseStamped>();
        tf = Transform{m.getHeader().getStampNs(),
                       m.getHeader().getFrameId().cStr(),
                       "odom",
                       m.getPose().getX(),
                       m.getPose().getY(),
                       m.getPose().getTheta()};
        break;
      }
      case Frames::kNone:
        break;
    }
  } catch (const kj::Exception& e) {
    throw MessageError(std::string("foxglove: frames: ") + e.getDescription().cStr());
  }
  writer_.write(t.channel, time_ns, json);
  // A transform needs two distinct named frames and a finite pose.
  if (!tf || tf->parent.empty() || tf->child.empty() || tf->parent == tf->child ||
      !std::isfinite(tf->x) || !std::isfinite(tf->y) || !std::isfinite(tf->theta))
    return;
  writer_.write(tfChannel(), time_ns,
                frameTransformJson(tf->stamp_ns, tf->parent, tf->child, tf->x, tf->y, tf->theta));
  ++transforms_;
}

}  // namespace tessera::viewer
