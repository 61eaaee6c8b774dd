// Tessera messages in Foxglove's terms (docs/viewer.md#foxglove-schemas): which well-known
// Foxglove schema a message type maps to, its JSON Schema, and each message as JSON, so MCAP
// exports (and the Foxglove bridge) open in Foxglove with its 3D, map and plot panels.
//
//   LaserScan        -> foxglove.LaserScan  (in its own frame, identity pose: the mount is a
//                                            transform, foxglove_mcap.hpp; no-return beams,
//                                            +inf or NaN, become 0: JSON has no inf)
//   OccupancyGrid    -> foxglove.Grid       (one int8 field "occupancy": -1 unknown, 0-100 %)
//   PoseStamped, GroundTruthPose, Odometry -> foxglove.PoseInFrame
//   Path             -> foxglove.PosesInFrame
//   PointCloud       -> foxglove.PointCloud  (x y z float32, + red green blue uint8 with colour)
//   LocalPlan        -> foxglove.SceneUpdate (entity "local_plan": every arc of the dynamic
//                                            window as a line, coloured by score, the chosen
//                                            one thick green; an empty plan deletes it)
//   CameraFootprints -> foxglove.SceneUpdate (entity "camera_<id>": floor polygon + label)
//   SubmapPoses      -> foxglove.SceneUpdate (entity "submap_<id>": arrow + id; replaces all)
//   LandmarkMap      -> foxglove.SceneUpdate (entity "landmarks": a sphere per landmark)
//   LineMap          -> foxglove.SceneUpdate (entity "lines": one line list of the extents)
// Every other message type is written as its own JSON (Cap'n Proto's JSON mapping, Data fields
// as base64) on a channel without a schema, which Foxglove shows in its raw message panel.
// Times: Header.stampNs as {sec, nsec}. Planar poses get z = 0 and a yaw-only quaternion.
#pragma once

#include <tessera/messages/message.hpp>

#include <cstdint>
#include <optional>
#include <string>

namespace tessera::viewer {

struct FoxgloveSchema {
  std::string name;      ///< e.g. "foxglove.Grid"; empty: schemaless JSON
  std::string encoding;  ///< "jsonschema", or empty without a schema
  std::string data;      ///< the JSON Schema text
};

/// The schema messages of `type_id` are written with (schemaless for types without a
/// well-known one). Throws MessageError for a type id Tessera does not define.
FoxgloveSchema foxgloveSchemaFor(std::uint64_t type_id);

/// One message of `type_id` as JSON text in the form foxgloveSchemaFor() describes. Throws
/// MessageError when the message cannot be read as that type.
std::string foxgloveJson(std::uint64_t type_id, const MessageStorage& message);

/// foxglove.FrameTransform (Tessera has no message of its own for it): its schema, and
/// `child` placed in `parent` by a planar pose [m, rad] at stamp_ns, as JSON.
FoxgloveSchema frameTransformSchema();
std::string frameTransformJson(std::int64_t stamp_ns, const std::string& parent,
                               const std::string& child, double x, double y, double theta);

/// Frames a topic's messages place (docs/viewer.md#frames): Odometry gives header frame (odom)
/// -> child frame (base_link), LaserScan gives base_link -> its header frame (the laser's
/// mount), and a PoseStamped topic named *map_to_odom gives its header frame (map) -> odom.
enum class FrameSource { kNone, kOdometry, kScanMount, kMapToOdom };
FrameSource frameSourceFor(const std::string& topic, std::uint64_t type_id);
/// The foxglove.FrameTransform JSON a message implies, or nothing (kNone, unnamed or equal
/// frames, a non-finite pose). Throws MessageError when it cannot be read.
std::optional<std::string> frameTransformFor(FrameSource source, const MessageStorage& message);

/// Whether Tessera defines `type_id` (every type a recording may hold).
bool knownMessageType(std::uint64_t type_id);

}  // namespace tessera::viewer
