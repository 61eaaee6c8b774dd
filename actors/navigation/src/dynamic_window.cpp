// DynamicWindow: sampled velocity pairs, arc rollouts against a distance field, normalised scores.
#include <tessera/navigation/dynamic_window.hpp>

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace tessera::navigation {

DistanceField::DistanceField(const Costmap& map)
    : geometry_(map), distance_(obstacleDistance(map)) {
  geometry_.cells.clear();
  geometry_.cells.shrink_to_fit();
}

double DistanceField::at(const Eigen::Vector2d& p) const {
  const Eigen::Vector2i c = geometry_.cellOf(p);
  if (!geometry_.contains(c)) return 0.0;
  return distance_[geometry_.index(c.x(), c.y())];
}

void DynamicWindowOptions::validate() const {
  ConfigCheck()
      .positive("max_speed", max_speed)
      .require(std::isfinite(min_speed) && min_speed <= max_speed, "min_speed",
               "must be <= max_speed", min_speed)
      .positive("max_turn_rate", max_turn_rate)
      .positive("acceleration", acceleration)
      .positive("turn_acceleration", turn_acceleration)
      .positive("brake", brake)
      .positive("period", period)
      .require(speed_samples >= 1, "speed_samples", "must be >= 1", speed_samples)
      .require(turn_samples >= 1, "turn_samples", "must be >= 1", turn_samples)
      .positive("horizon", horizon)
      .require(std::isfinite(step) && step > 0 && step <= horizon, "step",
               "must be in (0, horizon]", step)
      .nonNegative("footprint_radius", footprint_radius)
      .nonNegative("max_clearance", max_clearance)
      .nonNegative("heading_weight", heading_weight)
      .nonNegative("clearance_weight", clearance_weight)
      .nonNegative("velocity_weight", velocity_weight)
      .throwIfBad("dynamic window");
}

DynamicWindow::DynamicWindow(const DynamicWindowOptions& options) : options_(options) {
  options_.validate();
}

namespace {

/// Pose after driving the arc (v, w) for dt from p.
Pose2 advance(const Pose2& p, double v, double w, double dt) {
  if (std::abs(w) < 1e-9)
    return {p.x + v * dt * std::cos(p.theta), p.y + v * dt * std::sin(p.theta), p.theta};
  const double r = v / w, th = p.theta + w * dt;
  return {p.x + r * (std::sin(th) - std::sin(p.theta)),
          p.y - r * (std::cos(th) - std::cos(p.theta)), th};
}

std::vector<double> samples(double lo, double hi, int n) {
  if (n == 1 || hi - lo < 1e-12) return {0.5 * (lo + hi)};
  std::vector<double> out(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) out[static_cast<std::size_t>(i)] = lo + (hi - lo) * i / (n - 1);
  return out;
}

}  // namespace

DynamicWindowResult DynamicWindow::choose(const Pose2& pose, const Velocity& current,
                                          const Eigen::Vector2d& target,
                                          const DistanceField& obstacles, bool with_arcs) const {
  const DynamicWindowOptions& o = options_;
  DynamicWindowResult out;
  // A non-finite current velocity (a bad odometry message) counts as standing still.
  const double cv = std::isfinite(current.v) ? current.v : 0.0;
  const double cw = std::isfinite(current.w) ? current.w : 0.0;
  if (!pose.isFinite() || !target.allFinite()) return out;
  const double v_lo = std::clamp(cv - o.acceleration * o.period, o.min_speed, o.max_speed);
  const double v_hi = std::clamp(cv + o.acceleration * o.period, o.min_speed, o.max_speed);
  const double w_lo =
      std::clamp(cw - o.turn_acceleration * o.period, -o.max_turn_rate, o.max_turn_rate);
  const double w_hi =
      std::clamp(cw + o.turn_acceleration * o.period, -o.max_turn_rate, o.max_turn_rate);
  const std::vector<double> vs = samples(v_lo, v_hi, o.speed_samples);
  const std::vector<double> ws = samples(w_lo, w_hi, o.turn_samples);
  const std::size_t nv = vs.size(), nw = ws.size();

  struct Sample {
    bool admissible = false;
    double heading = 0, clearance = 0, velocity = 0, clear = 0, score = 0;
  };
  std::vector<Sample> grid(nv * nw);
  // The field measures to obstacle cell centres: half a cell more keeps the footprint off cells.
  const double reach = o.footprint_radius + 0.5 * obstacles.resolution();
  const int steps = static_cast<int>(std::ceil(o.horizon / o.step - 1e-9));
  double sum_heading = 0, sum_clearance = 0, sum_velocity = 0;
  for (std::size_t i = 0; i < nv; ++i)
    for (std::size_t j = 0; j < nw; ++j) {
      const double v = vs[i], w = ws[j];
      Sample& s = grid[i * nw + j];
      ++out.sampled;
      Pose2 p = pose;
      double clear = std::numeric_limits<double>::infinity();
      if (obstacles.at({p.x, p.y}) <= reach && v != 0) clear = 0;
      for (int k = 1; k <= steps && std::isinf(clear); ++k) {
        const Pose2 next = advance(p, v, w, o.step);
        if (obstacles.at({next.x, next.y}) <= reach) clear = std::abs(v) * o.step * (k - 1);
        p = next;
      }
      s.clear = clear;
      s.admissible = std::abs(v) <= std::sqrt(2.0 * clear * o.brake);
      if (!s.admissible) continue;
      ++out.admissible;
      const double bearing =
          normalizeAngle(std::atan2(target.y() - p.y, target.x() - p.x) - p.theta);
      s.heading = std::numbers::pi - std::abs(bearing);
      s.clearance = std::min(clear, o.max_clearance);
      s.velocity = v - std::min(0.0, o.min_speed);
      sum_heading += s.heading;
      sum_clearance += s.clearance;
      sum_velocity += s.velocity;
    }
  // Every sample's arc over the whole horizon, only when asked for (a second rollout of each).
  const auto arcs = [&](const std::vector<double>& score) {
    if (!with_arcs) return;
    out.arcs.resize(grid.size());
    for (std::size_t n = 0; n < grid.size(); ++n) {
      const Sample& s = grid[n];
      DynamicWindowArc& a = out.arcs[n];
      a.velocity = {vs[n / nw], ws[n % nw]};
      a.admissible = s.admissible;
      a.score = s.admissible && !score.empty() ? score[n] : 0.0;
      a.clearance = std::min(s.clear, std::abs(a.velocity.v) * o.step * steps);
      a.poses.reserve(static_cast<std::size_t>(steps) + 1);
      Pose2 p = pose;
      a.poses.push_back(p);
      for (int k = 1; k <= steps; ++k) {
        p = advance(p, a.velocity.v, a.velocity.w, o.step);
        a.poses.push_back(p);
      }
    }
  };
  if (out.admissible == 0) {
    arcs({});
    return out;
  }
  auto norm = [](double x, double sum) { return sum > 0 ? x / sum : 0.0; };
  for (Sample& s : grid)
    if (s.admissible)
      s.score = o.heading_weight * norm(s.heading, sum_heading) +
                o.clearance_weight * norm(s.clearance, sum_clearance) +
                o.velocity_weight * norm(s.velocity, sum_velocity);
  std::vector<double> score(grid.size(), -1.0);
  for (std::size_t i = 0; i < nv; ++i)
    for (std::size_t j = 0; j < nw; ++j) {
      const Sample& s = grid[i * nw + j];
      if (!s.admissible) continue;
      if (!o.smooth) {
        score[i * nw + j] = s.score;
        continue;
      }
      double total = 0;
      int n = 0;
      auto add = [&](std::size_t a, std::size_t b) {
        if (grid[a * nw + b].admissible) total += grid[a * nw + b].score, ++n;
      };
      add(i, j);
      if (i > 0) add(i - 1, j);
      if (i + 1 < nv) add(i + 1, j);
      if (j > 0) add(i, j - 1);
      if (j + 1 < nw) add(i, j + 1);
      score[i * nw + j] = total / n;
    }
  const std::size_t best =
      static_cast<std::size_t>(std::max_element(score.begin(), score.end()) - score.begin());
  out.ok = true;
  out.chosen = static_cast<int>(best);
  out.command = {vs[best / nw], ws[best % nw]};
  out.clearance = grid[best].clear;
  Pose2 p = pose;
  out.rollout.push_back(p);
  for (int k = 1; k <= steps; ++k) {
    p = advance(p, out.command.v, out.command.w, o.step);
    out.rollout.push_back(p);
  }
  arcs(score);
  return out;
}

}  // namespace tessera::navigation
