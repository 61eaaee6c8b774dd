// Subscribe to a stream of planar poses carried by one of several message types, chosen by an
// option, and hand (stamp, Pose2) to a callback. Shared by the mapping, localisation and
// navigation actors.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <string>
#include <string_view>
#include <utility>

namespace tessera {

enum class PoseMessage { kGroundTruth, kOdometry, kPoseStamped };

/// Accepted values of a `*message` option, for docs and errors.
inline constexpr const char* kPoseMessageChoices = "ground_truth | odometry | pose_stamped";

/// Parses an option value; throws ConfigError naming the actor type, key and the choices.
inline PoseMessage parsePoseMessage(const std::string& value, std::string_view actor,
                                    std::string_view key) {
  if (value == "ground_truth") return PoseMessage::kGroundTruth;
  if (value == "odometry") return PoseMessage::kOdometry;
  if (value == "pose_stamped") return PoseMessage::kPoseStamped;
  throw ConfigError(std::string(actor) + ": option '" + std::string(key) + "' is '" + value +
                    "', expected one of " + kPoseMessageChoices);
}

/// Subscribes `topic` with the message type `kind` selects; calls on_pose(stamp_ns, pose).
template <typename OnPose>
void subscribePoses(ActorContext& ctx, std::string_view topic, MailboxPolicy policy,
                    PoseMessage kind, OnPose on_pose) {
  switch (kind) {
    case PoseMessage::kGroundTruth:
      ctx.subscribe<msg::GroundTruthPose>(topic, policy, [on_pose](const auto& m) {
        on_pose(m->getHeader().getStampNs(), toPose2(m->getPose()));
      });
      break;
    case PoseMessage::kOdometry:
      ctx.subscribe<msg::Odometry>(topic, policy, [on_pose](const auto& m) {
        on_pose(m->getHeader().getStampNs(), toPose2(m->getPose()));
      });
      break;
    case PoseMessage::kPoseStamped:
      ctx.subscribe<msg::PoseStamped>(topic, policy, [on_pose](const auto& m) {
        on_pose(m->getHeader().getStampNs(), toPose2(m->getPose()));
      });
      break;
  }
}

}  // namespace tessera
