#include <tessera/navigation/goal_sequencer_actor.hpp>

#include <tessera/actor_common/map_message.hpp>
#include <tessera/actor_common/pose_source.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/navigation/grid_planner.hpp>
#include <tessera/runtime/registry.hpp>

#include <cmath>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::navigation {

namespace {

constexpr const char* kName = "goal_sequencer";

[[noreturn]] void fail(const std::string& key, const std::string& rule) {
  throw ConfigError(std::string(kName) + ": option '" + key + "' " + rule);
}

}  // namespace

std::vector<GoalSpec> readGoalsFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("cannot open '" + path + "'");
  std::vector<GoalSpec> goals;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (const auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<double> v;
    std::string token;
    while (fields >> token) {
      std::size_t used = 0;
      double d = 0;
      try {
        d = std::stod(token, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != token.size() || !std::isfinite(d))
        throw std::invalid_argument(path + ":" + std::to_string(number) + ": '" + token +
                                    "' is not a finite number");
      v.push_back(d);
    }
    if (v.empty()) continue;
    if (v.size() < 3 || v.size() > 5)
      throw std::invalid_argument(path + ":" + std::to_string(number) + ": " +
                                  std::to_string(v.size()) +
                                  " numbers, expected 'x y theta [tolerance_xy [tolerance_yaw]]'");
    GoalSpec g;
    g.pose = Pose2(v[0], v[1], v[2]);
    if (v.size() > 3) g.tolerance_xy = v[3];
    if (v.size() > 4) g.tolerance_yaw = v[4];
    goals.push_back(g);
  }
  if (goals.empty()) throw std::invalid_argument("'" + path + "' holds no goal");
  return goals;
}

std::vector<Eigen::Vector2i> reachableCells(const Costmap& map, double clearance,
                                            const Eigen::Vector2d& start, Costmap* eroded) {
  Costmap e = map;
  // Unknown counts as an obstacle here: a goal there could not be shown to be reachable.
  for (auto& c : e.cells)
    if (c == cost::kUnknown) c = cost::kLethal;
  InflationOptions inflation;
  inflation.inscribed_radius = clearance;
  inflation.inflation_radius = clearance;
  inflate(e, inflation);
  for (auto& c : e.cells)
    if (c < cost::kInscribed) c = cost::kFree;  // only the region matters: no cost gradient
  std::vector<Eigen::Vector2i> out;
  const Eigen::Vector2i s = e.cellOf(start);
  if (e.contains(s) && e.at(s) < cost::kInscribed) {
    std::vector<std::uint8_t> seen(e.cells.size(), 0);
    std::deque<Eigen::Vector2i> open{s};
    seen[e.index(s.x(), s.y())] = 1;
    while (!open.empty()) {
      const Eigen::Vector2i c = open.front();
      open.pop_front();
      out.push_back(c);
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Eigen::Vector2i n(c.x() + dx, c.y() + dy);
          if (!e.contains(n) || e.at(n) >= cost::kInscribed) continue;
          auto& flag = seen[e.index(n.x(), n.y())];
          if (!flag) {
            flag = 1;
            open.push_back(n);
          }
        }
    }
  }
  if (eroded) *eroded = std::move(e);
  return out;
}

double shortestPathLength(const Costmap& eroded, const Eigen::Vector2d& a,
                          const Eigen::Vector2d& b) {
  GridPlannerOptions o;
  o.cost_weight = 0;
  GridPlanner planner(o);
  const GridPath path = planner.plan(eroded, eroded.cellOf(a), eroded.cellOf(b));
  if (!path.ok()) return std::numeric_limits<double>::quiet_NaN();
  const auto kept = shortenPath(eroded, path.cells, cost::kMaxTraversable);
  return pathLength(eroded, kept);
}

GoalSequencerActor::GoalSequencerActor(GoalSequencerOptions options)
    : options_(std::move(options)), rng_(options_.seed) {
  const auto& o = options_;
  parsePoseMessage(o.pose_message, kName, "pose_message");
  if (o.random < 0) fail("random", "must be >= 0");
  if (o.random > 0 && !o.goals_file.empty())
    fail("random", "and goals_file exclude each other: give one");
  if (o.random == 0 && o.goals_file.empty())
    fail("goals_file", "is empty and random is 0: give goals one way");
  for (auto [key, value] :
       {std::pair{"clearance", o.clearance}, std::pair{"goal_timeout_s", o.goal_timeout_s}})
    if (!(std::isfinite(value) && value > 0)) fail(key, "must be finite and > 0");
  for (auto [key, value] :
       {std::pair{"min_distance", o.min_distance}, std::pair{"start_delay_s", o.start_delay_s},
        std::pair{"tolerance_xy", o.tolerance_xy}})
    if (!(std::isfinite(value) && value >= 0)) fail(key, "must be finite and >= 0");
  if (o.frame_id.empty()) fail("frame_id", "must not be empty");
  if (!o.map_origin.empty()) {
    if (o.map_origin.size() != 3 ||
        !Eigen::Vector3d(o.map_origin[0], o.map_origin[1], o.map_origin[2]).allFinite())
      fail("map_origin", "must be [x, y, theta], finite");
    map_origin_ = Pose2(o.map_origin[0], o.map_origin[1], o.map_origin[2]);
  }
  if (!o.goals_file.empty()) {
    try {
      goals_ = readGoalsFile(o.goals_file);
    } catch (const std::invalid_argument& e) {
      fail("goals_file", e.what());
    }
    goals_ready_ = true;
  }
}

void GoalSequencerActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  subscribePoses(ctx, "pose", MailboxPolicy::keepLatest(4),
                 parsePoseMessage(options_.pose_message, kName, "pose_message"),
                 [this](Nanos stamp, const Pose2& pose) { onPose(stamp, pose); });
  ctx.subscribe<msg::NavStatus>("nav_status", MailboxPolicy::reliable(),
                                [this](const Message<msg::NavStatus>& m) { onStatus(m); });
  if (options_.random > 0)
    ctx.subscribe<msg::OccupancyGrid>("map", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::OccupancyGrid>& m) { onMap(m); });
  goal_pub_ = ctx.advertise<msg::NavGoal>("goal");
  ctx.declareFiniteSource();
  ctx.addTimer(kNanosPerSecond / 10, [this] { tick(); });
}

void GoalSequencerActor::onPose(Nanos, const Pose2& pose) {
  if (!pose.isFinite()) return;
  if (active_ && pose_)
    results_.back().driven_m += (pose.translation() - pose_->translation()).norm();
  pose_ = pose;
}

void GoalSequencerActor::onMap(const Message<msg::OccupancyGrid>& m) {
  if (map_) return;  // goals are drawn once, on the first map
  try {
    map_ = fromOccupancy(toOccupancyMap(*m));
  } catch (const std::invalid_argument& e) {
    std::cerr << "[" << ctx_->name() << "] map message: " << e.what() << "; skipped\n";
  }
}

bool GoalSequencerActor::drawGoals() {
  if (!map_ || !pose_) return false;
  const auto cells = reachableCells(*map_, options_.clearance, pose_->translation(), &eroded_);
  if (cells.empty()) {
    ctx_->requestStop(std::string(kName) + ": the robot's start (" + std::to_string(pose_->x) +
                      ", " + std::to_string(pose_->y) + ") is not in a region with clearance " +
                      std::to_string(options_.clearance) + " m: no goal can be drawn");
    done_ = true;
    return false;
  }
  std::uniform_int_distribution<std::size_t> pick(0, cells.size() - 1);
  std::uniform_real_distribution<double> heading(-std::numbers::pi, std::numbers::pi);
  Eigen::Vector2d previous = pose_->translation();
  for (int i = 0; i < options_.random; ++i) {
    Eigen::Vector2d p = map_->cellCenter(cells[pick(rng_)]);
    for (int tries = 0; tries < 1000 && (p - previous).norm() < options_.min_distance; ++tries)
      p = map_->cellCenter(cells[pick(rng_)]);
    GoalSpec g;
    g.pose = Pose2(p.x(), p.y(), heading(rng_));
    g.tolerance_xy = options_.tolerance_xy;
    g.tolerance_yaw = options_.tolerance_yaw;
    goals_.push_back(g);
    previous = p;
  }
  goals_ready_ = true;
  return true;
}

void GoalSequencerActor::tick() {
  if (done_) return;
  const Nanos now = ctx_->now();
  if (start_ < 0) start_ = now;
  if (!goals_ready_ && !drawGoals()) return;
  if (!active_) {
    if (nanosToSeconds(now - start_) >= options_.start_delay_s && pose_) sendNext();
    return;
  }
  if (nanosToSeconds(now - sent_at_) > options_.goal_timeout_s)
    finish("timed_out", "not ended within " + std::to_string(options_.goal_timeout_s) + " s");
}

void GoalSequencerActor::sendNext() {
  if (next_ >= goals_.size()) {
    done_ = true;
    ctx_->reportProgress(1.0);
    ctx_->finished();
    return;
  }
  const GoalSpec& g = goals_[next_++];
  Result r;
  r.id = next_;
  r.goal = g;
  r.outcome = "pending";
  if (!eroded_.empty() && pose_)
    r.shortest_m = shortestPathLength(eroded_, pose_->translation(), g.pose.translation());
  else if (pose_)
    r.shortest_m = (g.pose.translation() - pose_->translation()).norm();
  results_.push_back(r);
  sent_at_ = ctx_->now();
  active_ = true;
  auto loan = goal_pub_.loan();
  setHeader(loan->initHeader(), sent_at_, options_.frame_id, goal_pub_.nextSeq());
  writePose(loan->initPose(), map_origin_.inverse() * g.pose);
  loan->setId(r.id);
  loan->setToleranceXy(g.tolerance_xy);
  loan->setToleranceYaw(g.tolerance_yaw);
  goal_pub_.publish(std::move(loan));
  std::cerr << "[" << ctx_->name() << "] goal " << r.id << "/" << goals_.size() << ": ("
            << std::fixed << std::setprecision(2) << g.pose.x << ", " << g.pose.y << ", "
            << g.pose.theta << ")\n"
            << std::defaultfloat;
}

void GoalSequencerActor::onStatus(const Message<msg::NavStatus>& m) {
  if (!active_ || m->getGoalId() != results_.back().id) return;
  using S = msg::NavStatus::State;
  switch (m->getState()) {
    case S::REACHED:
      return finish("reached", "");
    case S::FAILED:
      return finish("failed", m->getReason());
    case S::REFUSED:
      return finish("refused", m->getReason());
    default:
      return;
  }
}

void GoalSequencerActor::finish(const std::string& outcome, const std::string& reason) {
  Result& r = results_.back();
  r.outcome = outcome;
  r.reason = reason;
  r.time_s = nanosToSeconds(ctx_->now() - sent_at_);
  active_ = false;
  std::cerr << "[" << ctx_->name() << "] goal " << r.id << " " << outcome << " after " << std::fixed
            << std::setprecision(1) << r.time_s << " s, " << r.driven_m << " m driven (shortest "
            << r.shortest_m << " m)" << std::defaultfloat << (reason.empty() ? "" : ": " + reason)
            << "\n";
  ctx_->reportProgress(static_cast<double>(next_) / static_cast<double>(goals_.size()));
  sendNext();
}

void GoalSequencerActor::stop() {
  if (options_.goals_csv.empty() || ctx_->outputDir().empty()) return;
  const auto path = std::filesystem::path(ctx_->outputDir()) / options_.goals_csv;
  std::ostringstream out;
  out << std::setprecision(10);
  out << "id,x,y,theta,outcome,time_s,driven_m,shortest_m,reason\n";
  for (const Result& r : results_)
    out << r.id << ',' << r.goal.pose.x << ',' << r.goal.pose.y << ',' << r.goal.pose.theta << ','
        << r.outcome << ',' << r.time_s << ',' << r.driven_m << ',' << r.shortest_m << ",\""
        << r.reason << "\"\n";
  // stop() must not throw: a failed write is reported (the old file, if any, stays whole).
  try {
    io::writeFileAtomically(path, out.str());
  } catch (const std::exception& e) {
    std::cerr << "[" << ctx_->name() << "] " << e.what() << "\n";
  }
}

void GoalSequencerActor::summarize(Summary& out) const {
  std::int64_t reached = 0, failed = 0, refused = 0, timed_out = 0;
  double time = 0, ratio = 0, driven = 0;
  std::int64_t ratios = 0;
  for (const Result& r : results_) {
    driven += r.driven_m;
    if (r.outcome == "reached") {
      ++reached;
      time += r.time_s;
      if (r.shortest_m > 0.05 && std::isfinite(r.shortest_m)) {
        ratio += r.driven_m / r.shortest_m;
        ++ratios;
      }
    }
    failed += r.outcome == "failed";
    refused += r.outcome == "refused";
    timed_out += r.outcome == "timed_out";
  }
  out["goals"] = static_cast<std::int64_t>(results_.size());
  out["goals_planned"] = static_cast<std::int64_t>(goals_.size());
  out["reached"] = reached;
  out["failed"] = failed;
  out["refused"] = refused;
  out["timed_out"] = timed_out;
  out["mean_time_to_goal_s"] = reached > 0 ? time / static_cast<double>(reached) : 0.0;
  out["path_length_ratio"] = ratios > 0 ? ratio / static_cast<double>(ratios) : 0.0;
  out["driven_m"] = driven;
}

TESSERA_REGISTER_ACTOR("goal_sequencer", GoalSequencerActor, GoalSequencerOptions,
                       "sends navigation goals one by one (goals file or random reachable "
                       "goals) and measures time to goal and path length");

}  // namespace tessera::navigation
