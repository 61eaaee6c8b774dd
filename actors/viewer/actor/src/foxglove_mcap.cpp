// FoxgloveMcap: channels per topic, and the frame transforms odometry, scans and the
// localiser's map_to_odom imply, on one "tf" channel.
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>

#include <optional>

namespace tessera::viewer {

std::size_t FoxgloveMcap::addTopic(const std::string& topic, std::uint64_t type_id,
                                   const std::string& type_name) {
  if (!knownMessageType(type_id))
    throw MessageError("foxglove: topic '" + topic + "' has type " + type_name +
                       ", unknown to this build");
  const FrameSource frames = frameSourceFor(topic, type_id);
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
  const std::optional<std::string> tf = frameTransformFor(t.frames, message);
  writer_.write(t.channel, time_ns, json);
  if (!tf) return;
  writer_.write(tfChannel(), time_ns, *tf);
  ++transforms_;
}

}  // namespace tessera::viewer
