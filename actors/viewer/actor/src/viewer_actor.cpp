#include <tessera/viewer/viewer_actor.hpp>

#include <tessera/msg/map.capnp.h>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/viewer/foxglove_json.hpp>

#include <kj/exception.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>

namespace tessera::viewer {

std::vector<StaticFile> webAssets();  // the page, embedded at build time (cmake/EmbedFiles.cmake)

struct ViewerActor::Topic {
  std::string name;
  std::uint64_t type_id = 0;
  std::uint32_t channel = 0;        // its Foxglove form; 0: nobody publishes the topic
  std::uint32_t tiles_channel = 0;  // occupancy grids: the tiles
  FrameSource frames = FrameSource::kNone;
  std::unique_ptr<MapTiler> tiler;
  // The newest message (guarded by ViewerActor::latest_mutex_): converted when a client
  // subscribes to a channel that was published before anyone looked.
  std::shared_ptr<const MessageStorage> latest;
};

namespace {

bool isGrid(std::uint64_t type_id) {
  return type_id == messageTypeOf<msg::OccupancyGrid>().id;
}

}  // namespace

std::string parseClientPose(std::string_view payload, ClientPose& out) {
  const auto j = nlohmann::json::parse(payload, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return "expected a JSON object";
  auto number = [](const nlohmann::json& o, const char* key, double& v) {
    if (!o.contains(key) || !o[key].is_number()) return false;
    v = o[key].get<double>();
    return true;
  };
  if (j.contains("x") || j.contains("y")) {
    if (!number(j, "x", out.x) || !number(j, "y", out.y)) return "x and y must be numbers [m]";
    if (j.contains("theta") && !number(j, "theta", out.theta)) return "theta must be a number";
  } else {
    const nlohmann::json* pose = &j;
    if (j.contains("pose") && j["pose"].is_object()) pose = &j["pose"];
    if (!pose->contains("position") || !(*pose)["position"].is_object())
      return "expected {\"x\",\"y\",\"theta\"} or a pose with position and orientation";
    const auto& p = (*pose)["position"];
    if (!number(p, "x", out.x) || !number(p, "y", out.y))
      return "position.x and position.y must be numbers [m]";
    if (pose->contains("orientation") && (*pose)["orientation"].is_object()) {
      const auto& q = (*pose)["orientation"];
      double qz = 0, qw = 1, qx = 0, qy = 0;
      number(q, "x", qx), number(q, "y", qy), number(q, "z", qz), number(q, "w", qw);
      out.theta = std::atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz));
    }
  }
  if (!std::isfinite(out.x) || !std::isfinite(out.y) ||
      (!std::isnan(out.theta) && !std::isfinite(out.theta)))
    return "the pose must be finite";
  return "";
}

namespace {

std::int64_t wallNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

std::string metricsJson(const RunSnapshot& now, RunSnapshot& last) {
  nlohmann::json j;
  j["wall_s"] = now.wall_s;
  j["sim_s"] = now.sim_s;
  j["progress"] = now.progress >= 0 ? nlohmann::json(now.progress) : nlohmann::json(nullptr);
  j["actors"] = nlohmann::json::array();
  const double dt = now.wall_s - last.wall_s;
  for (std::size_t i = 0; i < now.actors.size(); ++i) {
    const auto& a = now.actors[i];
    const bool before = i < last.actors.size() && last.actors[i].name == a.name && dt > 0;
    j["actors"].push_back(
        {{"name", a.name},
         {"messages_in", a.messages_in},
         {"messages_out", a.messages_out},
         {"drops", a.drops},
         {"queue_depth", a.queue_depth},
         {"max_queue_depth", a.max_queue_depth},
         {"busy_s", a.busy_s},
         {"in_per_s",
          before ? static_cast<double>(a.messages_in - last.actors[i].messages_in) / dt : 0.0},
         {"busy_pct", before ? 100.0 * (a.busy_s - last.actors[i].busy_s) / dt : 0.0}});
  }
  last = now;
  return j.dump();
}

ViewerActor::ViewerActor(ViewerActorOptions options) : options_(std::move(options)) {
  auto fail = [](const std::string& key, const std::string& what) {
    throw ConfigError("viewer: option '" + key + "': " + what);
  };
  if (options_.port < 0 || options_.port > 65535) fail("port", "must be in 0..65535");
  if (options_.address.empty()) fail("address", "is required (e.g. 127.0.0.1)");
  if (options_.max_clients < 1 || options_.max_clients > 1024)
    fail("max_clients", "must be in 1..1024");
  if (options_.max_buffered_kib < 64) fail("max_buffered_kib", "must be >= 64");
  if (options_.max_client_message_kib < 1 || options_.max_client_message_kib > 16384)
    fail("max_client_message_kib", "must be in 1..16384");
  if (options_.tile_size < 8 || options_.tile_size > 512) fail("tile_size", "must be in 8..512");
  if (options_.queue < 1) fail("queue", "must be >= 1");
  for (std::size_t i = 0; i < options_.topics.size(); ++i)
    for (std::size_t k = 0; k < i; ++k)
      if (options_.topics[i] == options_.topics[k])
        fail("topics", "lists '" + options_.topics[i] + "' twice");
}

ViewerActor::~ViewerActor() = default;

void ViewerActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  for (std::size_t i = 0; i < options_.topics.size(); ++i) {
    auto t = std::make_unique<Topic>();
    t->name = options_.topics[i];
    topics_.push_back(std::move(t));
    ctx.subscribeUntyped(
        options_.topics[i], kAnyMessageType,
        MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.queue)).asOptional(),
        [this, i](const std::shared_ptr<const MessageStorage>& m) { onMessage(i, m); });
  }
  if (!options_.goal_topic.empty()) goal_pub_ = ctx.advertise<msg::NavGoal>(options_.goal_topic);
  if (!options_.initial_pose_topic.empty())
    initial_pose_pub_ = ctx.advertise<msg::PoseStamped>(options_.initial_pose_topic);
}

void ViewerActor::start() {
  FoxgloveServerOptions so;
  so.address = options_.address;
  so.port = static_cast<int>(options_.port);
  so.token = options_.token;
  so.allowed_origins = options_.allowed_origins;
  so.max_clients = static_cast<std::size_t>(options_.max_clients);
  so.max_buffered_kib = static_cast<std::size_t>(options_.max_buffered_kib);
  so.max_client_message_kib = static_cast<std::size_t>(options_.max_client_message_kib);
  try {
    server_ = std::make_unique<FoxgloveServer>(so, webAssets());
  } catch (const ServerError& e) {
    throw ConfigError(e.what());
  }
  bool frames = false;
  for (auto& t : topics_) {
    const MessageType type = ctx_->topicType(t->name);
    if (type.id == kAnyMessageType.id || !knownMessageType(type.id)) continue;  // unpublished
    t->type_id = type.id;
    const FoxgloveSchema schema = foxgloveSchemaFor(type.id);
    t->channel = server_->addChannel(
        {t->name, "json", schema.name.empty() ? std::string("tessera.") + type.name : schema.name,
         schema.data, schema.name.empty() ? "" : schema.encoding});
    if (isGrid(type.id)) {
      t->tiles_channel =
          server_->addChannel({t->name + "/tiles", "tessera.tiles", "tessera.MapTiles", "", ""});
      t->tiler = std::make_unique<MapTiler>(static_cast<int>(options_.tile_size));
    }
    t->frames = frameSourceFor(t->name, type.id);
    frames = frames || t->frames != FrameSource::kNone;
  }
  // The run's live figures, once a second while someone looks.
  const std::uint32_t metrics =
      server_->addChannel({"tessera/metrics", "json", "tessera.Metrics", "", ""});
  server_->publishEvery(metrics, 1000, [this, last = RunSnapshot{}]() mutable {
    return metricsJson(ctx_->snapshot(), last);
  });
  if (frames) {
    const FoxgloveSchema tf = frameTransformSchema();
    tf_channel_ = server_->addChannel({"tf", "json", tf.name, tf.data, tf.encoding});
  }
  server_->onSubscribe([this](std::uint32_t channel) { onFirstSubscriber(channel); });
  if (goal_pub_.valid())
    server_->acceptClientTopic(options_.goal_topic,
                               [this](std::string_view p) { return onGoal(p); });
  if (initial_pose_pub_.valid())
    server_->acceptClientTopic(options_.initial_pose_topic,
                               [this](std::string_view p) { return onInitialPose(p); });
  const std::string host = options_.address == "0.0.0.0" || options_.address == "::"
                               ? std::string("THIS-HOST")
                               : options_.address;
  url_ = "http://" + host + ":" + std::to_string(server_->port()) + "/";
  // The token is printed for the user, never stored in the summary.
  std::cerr << "[" << ctx_->name() << "] live view: " << url_
            << (options_.token.empty() ? "" : "?token=" + options_.token)
            << "  (Foxglove Studio: ws://" << host << ":" << server_->port() << ")\n";
}

void ViewerActor::onMessage(std::size_t index, const std::shared_ptr<const MessageStorage>& m) {
  Topic& t = *topics_[index];
  if (!server_ || t.channel == 0) return;
  const auto stamp = static_cast<std::uint64_t>(std::max<Nanos>(ctx_->now(), 0));
  try {
    if (t.tiler) {
      // Tiles are kept current whether or not anyone looks: a browser that connects later
      // gets the whole map from the tiles at once.
      const std::int64_t received = wallNs();
      const auto g = m->root().getAs<msg::OccupancyGrid>();
      const auto cells = g.getCells();
      if (g.getWidth() > 1u << 30 || g.getHeight() > 1u << 30)
        throw MessageError("grid of " + std::to_string(g.getWidth()) + " x " +
                           std::to_string(g.getHeight()) + " cells is too large to draw");
      GridView view;
      view.resolution = g.getResolution();
      view.width = static_cast<int>(g.getWidth());
      view.height = static_cast<int>(g.getHeight());
      view.origin_x = g.getOrigin().getX();
      view.origin_y = g.getOrigin().getY();
      view.origin_theta = g.getOrigin().getTheta();
      view.cells = reinterpret_cast<const std::int8_t*>(cells.begin());
      view.cell_count = cells.size();
      MapTiler::Update u;
      try {
        u = t.tiler->update(view, g.getHeader().getStampNs(), received);
      } catch (const std::invalid_argument& e) {
        throw MessageError(e.what());
      }
      tiles_sent_ += u.tiles.size();
      ++map_updates_;
      server_->publishParts(t.tiles_channel, stamp, u.epoch, std::move(u.header),
                            std::move(u.tiles));
    }
    {
      // Kept for a later first subscriber; the lock orders this publish and that one.
      std::lock_guard<std::mutex> lock(latest_mutex_);
      if (!t.tiler) t.latest = m;
      if (server_->subscribed(t.channel))
        server_->publish(t.channel, stamp, foxgloveJson(t.type_id, *m));
    }
    if (tf_channel_ && t.frames != FrameSource::kNone && server_->subscribed(tf_channel_))
      if (auto tf = frameTransformFor(t.frames, *m)) server_->publish(tf_channel_, stamp, *tf);
  } catch (const MessageError& e) {
    if (++unreadable_ <= 5)
      std::cerr << "[" << ctx_->name() << "] " << t.name << ": " << e.what() << "; skipped\n";
  } catch (const kj::Exception& e) {
    if (++unreadable_ <= 5)
      std::cerr << "[" << ctx_->name() << "] " << t.name << ": " << e.getDescription().cStr()
                << "; skipped\n";
  }
}

void ViewerActor::onFirstSubscriber(std::uint32_t channel) {
  std::lock_guard<std::mutex> lock(latest_mutex_);
  if (stopping_) return;  // the server is going away
  for (auto& t : topics_) {
    if (t->channel != channel || !t->latest) continue;
    try {
      const auto stamp = static_cast<std::uint64_t>(std::max<Nanos>(ctx_->now(), 0));
      server_->publish(channel, stamp, foxgloveJson(t->type_id, *t->latest));
    } catch (const MessageError&) {
      // Already reported when it arrived (onMessage).
    } catch (const kj::Exception&) {
    }
  }
}

std::string ViewerActor::onGoal(std::string_view payload) {
  ClientPose p;
  if (std::string e = parseClientPose(payload, p); !e.empty()) return e;
  const std::uint64_t n = ++goals_;
  auto loan = goal_pub_.loan();
  setHeader(loan->initHeader(), ctx_->now(), "map", goal_pub_.nextSeq());
  writePose(loan->initPose(), Pose2{p.x, p.y, std::isnan(p.theta) ? 0.0 : p.theta});
  // Ids apart from other goal sources' small counters.
  loan->setId(1'000'000 + n);
  loan->setToleranceXy(0);
  loan->setToleranceYaw(std::isnan(p.theta) ? std::numeric_limits<double>::quiet_NaN() : 0.0);
  goal_pub_.publish(std::move(loan));
  std::cerr << "[" << ctx_->name() << "] goal " << 1'000'000 + n << " from a client: (" << p.x
            << ", " << p.y << ", " << (std::isnan(p.theta) ? 0.0 : p.theta) << ")\n";
  return "";
}

std::string ViewerActor::onInitialPose(std::string_view payload) {
  ClientPose p;
  if (std::string e = parseClientPose(payload, p); !e.empty()) return e;
  ++initial_poses_;
  auto loan = initial_pose_pub_.loan();
  setHeader(loan->initHeader(), ctx_->now(), "map", initial_pose_pub_.nextSeq());
  writePose(loan->initPose(), Pose2{p.x, p.y, std::isnan(p.theta) ? 0.0 : p.theta});
  initial_pose_pub_.publish(std::move(loan));
  return "";
}

void ViewerActor::stop() {
  if (!server_) return;
  {
    // After this no subscription handler touches the server (one running has finished).
    std::lock_guard<std::mutex> lock(latest_mutex_);
    stopping_ = true;
  }
  final_stats_ = server_->stats();
  server_.reset();
}

void ViewerActor::summarize(Summary& out) const {
  const auto s = server_ ? server_->stats() : final_stats_;
  out["url"] = url_;
  out["clients_total"] = static_cast<std::int64_t>(s.clients_total);
  out["messages_sent"] = static_cast<std::int64_t>(s.messages_sent);
  out["mb_sent"] = static_cast<double>(s.bytes_sent) / 1e6;
  out["drops"] = static_cast<std::int64_t>(s.drops);
  out["rejected"] = static_cast<std::int64_t>(s.rejected);
  out["protocol_errors"] = static_cast<std::int64_t>(s.protocol_errors);
  out["goals"] = static_cast<std::int64_t>(goals_.load());
  out["initial_poses"] = static_cast<std::int64_t>(initial_poses_.load());
  out["map_updates"] = static_cast<std::int64_t>(map_updates_.load());
  out["tiles_sent"] = static_cast<std::int64_t>(tiles_sent_.load());
  out["unreadable"] = static_cast<std::int64_t>(unreadable_);
}

TESSERA_REGISTER_ACTOR("viewer", ViewerActor, ViewerActorOptions,
                       "live view: web page + Foxglove WebSocket bridge (tessera run --view PORT)");

}  // namespace tessera::viewer
