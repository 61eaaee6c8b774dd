// FoxgloveMcap: Tessera messages into an McapWriter in Foxglove's forms (foxglove_json.hpp;
// docs/viewer.md#frames), shared by `tessera replay --export` and the mcap_recorder actor.
//
// Each topic gets a channel (a schema per message type, added once). Messages that place frames
// also go, as foxglove.FrameTransform, onto one "tf" channel, so Foxglove's 3D panel can draw
// scans, poses and maps together: Odometry gives header frame (odom) → child frame (base_link),
// LaserScan gives base_link → its header frame (the laser's mount), and a PoseStamped topic named
// map_to_odom (the localiser's) gives its header frame (map) → odom. The writer is borrowed.
#pragma once

#include <tessera/messages/message.hpp>
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/mcap_writer.hpp>

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace tessera::viewer {

class FoxgloveMcap {
 public:
  explicit FoxgloveMcap(McapWriter& writer) : writer_(writer) {}

  /// Adds `topic` with messages of `type_id` (named `type_name` in the channel's metadata);
  /// returns its index for write(). Throws MessageError for a type this build does not define.
  std::size_t addTopic(const std::string& topic, std::uint64_t type_id,
                       const std::string& type_name);
  /// One message of topic `topic` logged at `time_ns`, and the transforms it implies. Throws
  /// MessageError (nothing written) when it cannot be read as its type, McapError on a write
  /// failure.
  void write(std::size_t topic, std::uint64_t time_ns, const MessageStorage& message);

  std::uint64_t transforms() const { return transforms_; }  ///< FrameTransforms written

 private:
  struct Topic {
    std::uint64_t type_id;
    std::uint16_t channel;
    FrameSource frames;
  };
  std::uint16_t tfChannel();

  McapWriter& writer_;
  std::vector<Topic> topics_;
  std::map<std::uint64_t, std::uint16_t> schemas_;  ///< message type -> schema id
  std::uint16_t tf_channel_ = 0;
  std::uint64_t transforms_ = 0;
};

}  // namespace tessera::viewer
