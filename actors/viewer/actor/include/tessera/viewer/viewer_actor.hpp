// ViewerActor ("viewer"): the live viewer (docs/viewer.md#live). Serves Tessera's web page and
// Foxglove's WebSocket protocol on one port (FoxgloveServer), so a browser at
// http://127.0.0.1:8765/ or Foxglove Studio ("Open connection", ws://127.0.0.1:8765) watches a
// running stack; `tessera run PROFILE --view 8765` adds it.
//
// Every listed topic that something publishes becomes a channel in its Foxglove form
// (foxglove_json.hpp), frames go onto "tf", and each occupancy-grid topic T also gets "T/tiles":
// the map as tiles, only the changed ones per update (map_tiles.hpp). A message is converted
// only while some client subscribes to its channel, and the server keeps only the newest per
// channel: a slow or absent browser costs the pipeline nothing but the mailbox hand-off.
//
// Clients may publish a navigation goal on `goal_topic` and an initial pose for localisation on
// `initial_pose_topic` (JSON {"x","y","theta"} in metres/radians, or a Foxglove/ROS pose with
// position and orientation); they become NavGoal / PoseStamped messages in the map frame.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/viewer/foxglove_server.hpp>
#include <tessera/viewer/map_tiles.hpp>

#include <tessera/msg/common.capnp.h>
#include <tessera/msg/navigation.capnp.h>

#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::viewer {

struct ViewerActorOptions {
  std::int64_t port = 8765;
  std::string address = "127.0.0.1";
  std::string token;
  std::vector<std::string> allowed_origins = {"https://app.foxglove.dev"};
  std::vector<std::string> topics = {"map",
                                     "scan",
                                     "pose",
                                     "localized_pose",
                                     "odom",
                                     "map_to_odom",
                                     "trajectory_final",
                                     "ground_truth",
                                     "submap_poses",
                                     "constraints",
                                     "path",
                                     "nav_status",
                                     "landmark_map",
                                     "line_map",
                                     "costmap",
                                     "local_plan",
                                     "map_cloud",
                                     "camera_footprints"};
  std::string goal_topic = "goal";
  std::string initial_pose_topic = "initial_pose";
  std::int64_t max_clients = 16;
  std::int64_t max_buffered_kib = 4096;
  std::int64_t max_client_message_kib = 64;
  std::int64_t tile_size = 64;
  std::int64_t queue = 16;

  template <class V>
  void visit(V& v) {
    v("port", port, "TCP port of the page and the Foxglove WebSocket (0: any free port)");
    v("address", address,
      "interface to listen on: 127.0.0.1 (this machine only), 0.0.0.0 (every interface; set "
      "a token)");
    v("token", token, "when set, every request needs ?token=TOKEN (or Authorization: Bearer)");
    v("allowed_origins", allowed_origins,
      "web origins besides the page itself whose browsers may connect (Foxglove's web app)");
    v("topics", topics, "topics to show; those nobody publishes are left out");
    v("goal_topic", goal_topic, "where clicked goals go (NavGoal); empty: no goals");
    v("initial_pose_topic", initial_pose_topic,
      "where clicked initial poses go (PoseStamped); empty: none");
    v("max_clients", max_clients, "simultaneous browser / Foxglove connections");
    v("max_buffered_kib", max_buffered_kib,
      "per client: bytes queued on its socket above which newer messages wait (and replace)");
    v("max_client_message_kib", max_client_message_kib,
      "larger messages from a client close its connection");
    v("tile_size", tile_size, "map tile edge [cells]");
    v("queue", queue, "keep-latest mailbox per topic [messages]");
  }
};

/// A pose a client sent: {"x","y","theta"} [m, m, rad], or a pose with position and orientation
/// (Foxglove PoseInFrame; ROS PoseStamped as {"pose": {...}}). theta stays NaN when not given.
struct ClientPose {
  double x = 0, y = 0, theta = std::numeric_limits<double>::quiet_NaN();
};
/// Reads `payload` into `out`; returns "" or what is wrong with it (for the client).
std::string parseClientPose(std::string_view payload, ClientPose& out);

/// The "tessera/metrics" message: the run's figures and, per actor, rates over the time since
/// `last` (which becomes `now`). JSON: {wall_s, sim_s, progress (null without finite sources),
/// actors: [{name, messages_in, messages_out, drops, queue_depth, max_queue_depth, busy_s,
/// in_per_s, busy_pct}]}.
std::string metricsJson(const RunSnapshot& now, RunSnapshot& last);

class ViewerActor final : public Actor {
 public:
  explicit ViewerActor(ViewerActorOptions options);  // throws ConfigError
  ~ViewerActor() override;
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// port, url, clients_total, messages_sent, mb_sent, drops, rejected, protocol_errors,
  /// goals, initial_poses, map_updates, tiles_sent_per_update.
  void summarize(Summary& out) const override;

 private:
  struct Topic;
  void onMessage(std::size_t topic, const std::shared_ptr<const MessageStorage>& message);
  /// A client subscribed to a channel that holds no message: publish the topic's newest.
  void onFirstSubscriber(std::uint32_t channel);
  std::string onGoal(std::string_view payload);
  std::string onInitialPose(std::string_view payload);

  ViewerActorOptions options_;
  ActorContext* ctx_ = nullptr;
  std::unique_ptr<FoxgloveServer> server_;
  std::vector<std::unique_ptr<Topic>> topics_;
  std::mutex latest_mutex_;  ///< Topic::latest, stopping_, and publishing in arrival order
  bool stopping_ = false;
  std::uint32_t tf_channel_ = 0;
  Publisher<msg::NavGoal> goal_pub_;
  Publisher<msg::PoseStamped> initial_pose_pub_;
  std::atomic<std::uint64_t> goals_{0}, initial_poses_{0}, map_updates_{0}, tiles_sent_{0};
  std::uint64_t unreadable_ = 0;
  FoxgloveServer::Stats final_stats_;
  std::string url_;
};

}  // namespace tessera::viewer
