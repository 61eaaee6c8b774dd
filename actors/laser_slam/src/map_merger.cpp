#include <tessera/laser_slam/map_merger.hpp>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <list>
#include <numbers>
#include <set>
#include <stdexcept>
#include <tuple>

namespace tessera::laser_slam {
namespace map_merger_detail {

using tessera::Pose2;
using tessera::grid::OccupancyMap;
using tessera::scan_matching::CorrelativeMatcher;
using tessera::scan_matching::GridView;
using tessera::scan_matching::MatchGrid;
using tessera::scan_matching::SearchWindow;

/// Key of a submap in the MapAssembler and the pyramid cache: robot · stride + id.
constexpr std::int64_t kIdStride = std::int64_t{1} << 24;
int keyOf(int robot, int id) {
  return static_cast<int>(robot * kIdStride + id);
}

struct Patch {
  Pose2 pose;  // in the submap's frame
  std::int64_t stamp_ns = 0;
  std::vector<Eigen::Vector2d> fine, coarse;  // occupied cells in the patch's frame
};

struct Submap {
  int id = 0;
  Pose2 pose;                                        // origin in the robot's frame
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // grid centre, submap frame
  double half_extent = 0.0;                          // [m] larger half-side of the grid
  double radius = 0.0;                               // [m] half-diagonal
  MatchGrid coarse{GridView{}, 0, 0.0};              // coarse pyramid
};

struct PairState {
  bool joined = false;
  std::vector<std::size_t> closures;          // indices into MapMerger::closures_
  std::vector<InterRobotClosure> candidates;  // global matches not (yet) agreed on
};

struct CachedPyramid {
  int key = 0;  // keyOf(robot, submap)
  std::uint64_t used = 0;
  std::unique_ptr<MatchGrid> grid;
};

std::string checkOptions(const MapMergerOptions& o) {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(o.patch_spacing)) return "patch_spacing must be > 0 [m]";
  if (!positive(o.patch_radius)) return "patch_radius must be > 0 [m]";
  if (o.patch_radius > o.coarse.max_range || o.patch_radius > o.fine.max_range)
    return "patch_radius must not exceed coarse.max_range and fine.max_range (points beyond "
           "would be dropped)";
  if (o.min_patch_points < 1) return "min_patch_points must be >= 1";
  if (o.max_patch_points < o.min_patch_points)
    return "max_patch_points must be >= min_patch_points";
  if (o.occupied_percent < 1 || o.occupied_percent > 100)
    return "occupied_percent must be in [1, 100]";
  if (o.coarse_factor < 1 || o.coarse_factor > 64) return "coarse_factor must be in [1, 64]";
  if (!(o.coarse_max_ambiguity > 0 && o.coarse_max_ambiguity <= 1))
    return "coarse_max_ambiguity must be in (0, 1]";
  if (!positive(o.refine_window_linear) || !(o.refine_window_angular >= 0))
    return "refine windows must be > 0 [m] and >= 0 [rad]";
  if (!positive(o.joined_window_linear) || !(o.joined_window_angular >= 0))
    return "joined windows must be > 0 [m] and >= 0 [rad]";
  if (o.joined_candidates < 1) return "joined_candidates must be >= 1";
  if (o.min_agreeing < 1) return "min_agreeing must be >= 1";
  if (!(o.max_conflict_fraction >= 0 && o.max_conflict_fraction <= 1))
    return "max_conflict_fraction must be in [0, 1]";
  if (o.free_percent < 1 || o.free_percent > o.occupied_percent)
    return "free_percent must be in [1, occupied_percent]";
  if (!positive(o.agree_linear) || !positive(o.agree_angular))
    return "agree_linear and agree_angular must be > 0";
  if (o.fine_cache < 1) return "fine_cache must be >= 1";
  return "";
}

/// Cells max-pooled over factor × factor blocks (unknown only where the whole block is).
OccupancyMap coarsen(const OccupancyMap& g, int factor) {
  OccupancyMap c;
  c.resolution = g.resolution * factor;
  c.width = (g.width + factor - 1) / factor;
  c.height = (g.height + factor - 1) / factor;
  c.origin = g.origin;
  c.cells.assign(static_cast<std::size_t>(c.width) * c.height, OccupancyMap::kUnknown);
  for (int row = 0; row < g.height; ++row)
    for (int col = 0; col < g.width; ++col) {
      const std::int8_t v = g.at(col, row);
      if (v < 0) continue;
      std::int8_t& out = c.at(col / factor, row / factor);
      out = std::max(out, v);
    }
  return c;
}

Pose2 meanPose(const std::vector<Pose2>& poses) {
  double x = 0, y = 0, s = 0, c = 0;
  for (const auto& p : poses) {
    x += p.x;
    y += p.y;
    s += std::sin(p.theta);
    c += std::cos(p.theta);
  }
  const double n = static_cast<double>(poses.size());
  return {x / n, y / n, std::atan2(s, c)};
}

/// Occupied cells of `a` (at `a_in_b`, the pose of a's frame in b's) that fall on b's known
/// free space, with a cell of slack: {agreeing, conflicting} (cells on b's unknown are neither).
std::pair<std::size_t, std::size_t> conflicts(const OccupancyMap& a, const OccupancyMap& b,
                                              const Pose2& a_in_b, int occupied, int free) {
  std::size_t agreeing = 0, conflicting = 0;
  for (int row = 0; row < a.height; ++row)
    for (int col = 0; col < a.width; ++col) {
      if (a.at(col, row) < occupied) continue;
      const Eigen::Vector2i c = b.cellOf(a_in_b * a.cellCenter(col, row));
      bool any_occupied = false, all_free = true;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = c.x() + dx, y = c.y() + dy;
          const std::int8_t v = b.contains(x, y) ? b.at(x, y) : OccupancyMap::kUnknown;
          any_occupied = any_occupied || v >= occupied;
          all_free = all_free && v >= 0 && v < free;
        }
      if (any_occupied)
        ++agreeing;
      else if (all_free)
        ++conflicting;
    }
  return {agreeing, conflicting};
}

bool agree(const Pose2& a, const Pose2& b, const MapMergerOptions& o) {
  return std::hypot(a.x - b.x, a.y - b.y) <= o.agree_linear &&
         std::abs(tessera::angleDiff(a.theta, b.theta)) <= o.agree_angular;
}

}  // namespace map_merger_detail

using namespace map_merger_detail;

struct MapMerger::Impl {
  MapMergerOptions options;
  CorrelativeMatcher coarse, fine;
  scan_matching::LoopClosureVerifier verifier;
  std::vector<std::map<int, Submap>> robots;
  std::map<std::pair<int, int>, PairState> pairs;  // (lower robot, higher robot)
  MapAssembler assembler;
  std::list<CachedPyramid> cache;
  std::uint64_t clock = 0;

  explicit Impl(int n, MapMergerOptions o)
      : options(std::move(o)),
        coarse(options.coarse),
        fine(options.fine),
        verifier(options.verifier),
        robots(static_cast<std::size_t>(n)) {}

  const MatchGrid& finePyramid(int robot, int id) {
    const int key = keyOf(robot, id);
    ++clock;
    for (auto& c : cache)
      if (c.key == key) {
        c.used = clock;
        return *c.grid;
      }
    if (cache.size() >= static_cast<std::size_t>(options.fine_cache))
      cache.erase(std::min_element(cache.begin(), cache.end(),
                                   [](const auto& a, const auto& b) { return a.used < b.used; }));
    const auto cells = assembler.grid(key);
    auto grid = std::make_unique<MatchGrid>(fine.precompute(GridView::of(*cells)));
    cache.push_back({key, clock, std::move(grid)});
    return *cache.back().grid;
  }
};

MapMerger::MapMerger(int robots, MapMergerOptions options) : robots_(robots) {
  if (robots < 2) throw std::invalid_argument("map_merger: need at least 2 robots");
  if (robots >= 64) throw std::invalid_argument("map_merger: at most 63 robots");
  if (const std::string e = checkOptions(options); !e.empty())
    throw std::invalid_argument("map_merger: " + e);
  impl_ = std::make_unique<Impl>(robots, std::move(options));
}

MapMerger::~MapMerger() = default;
MapMerger::MapMerger(MapMerger&&) noexcept = default;
MapMerger& MapMerger::operator=(MapMerger&&) noexcept = default;

const scan_matching::LoopVerifierCounts& MapMerger::verifierCounts() const {
  return impl_->verifier.counts();
}

std::optional<Pose2> MapMerger::submapPose(int robot, int id) const {
  if (robot < 0 || robot >= robots_) return std::nullopt;
  const auto& r = impl_->robots[static_cast<std::size_t>(robot)];
  const auto it = r.find(id);
  if (it == r.end()) return std::nullopt;
  return it->second.pose;
}

Pose2 MapMerger::estimate(const InterRobotClosure& c) const {
  const Pose2 t = *submapPose(c.robot_a, c.submap_a);
  const Pose2 s = *submapPose(c.robot_b, c.submap_b);
  return t * c.match * c.patch.inverse() * s.inverse();
}

std::optional<Pose2> MapMerger::relativeFrame(int a, int b) const {
  if (a < 0 || b < 0 || a >= robots_ || b >= robots_) return std::nullopt;
  // Breadth-first over joined pairs; each edge's frame is the mean of its closures' estimates.
  std::vector<std::optional<Pose2>> frames(static_cast<std::size_t>(robots_));
  frames[static_cast<std::size_t>(a)] = Pose2();
  std::deque<int> queue{a};
  while (!queue.empty()) {
    const int m = queue.front();
    queue.pop_front();
    for (const auto& [key, pair] : impl_->pairs) {
      if (!pair.joined || (key.first != m && key.second != m)) continue;
      const int n = key.first == m ? key.second : key.first;
      if (frames[static_cast<std::size_t>(n)]) continue;
      std::vector<Pose2> estimates;
      for (const std::size_t k : pair.closures) {
        const auto& c = closures_[k];
        const Pose2 e = estimate(c);  // robot_b's frame in robot_a's
        estimates.push_back(c.robot_a == m ? e : e.inverse());
      }
      frames[static_cast<std::size_t>(n)] =
          *frames[static_cast<std::size_t>(m)] * meanPose(estimates);
      queue.push_back(n);
    }
  }
  return frames[static_cast<std::size_t>(b)];
}

std::optional<Pose2> MapMerger::frame(int robot) const {
  return relativeFrame(0, robot);
}

void MapMerger::setPose(int robot, int id, const Pose2& pose) {
  if (robot < 0 || robot >= robots_ || !pose.isFinite()) return;
  auto& r = impl_->robots[static_cast<std::size_t>(robot)];
  if (const auto it = r.find(id); it != r.end()) it->second.pose = pose;
}

std::string MapMerger::addSubmap(int robot, int id, OccupancyMap grid, const Pose2& pose,
                                 const std::vector<SubmapTrajectoryPose>& trajectory) {
  auto& o = impl_->options;
  if (robot < 0 || robot >= robots_) {
    ++counts_.submaps_rejected;
    return "robot " + std::to_string(robot) + " is not one of the " + std::to_string(robots_);
  }
  if (id < 0 || id >= kIdStride) {
    ++counts_.submaps_rejected;
    return "submap id " + std::to_string(id) + " is out of range";
  }
  if (!pose.isFinite()) {
    ++counts_.submaps_rejected;
    return "submap " + std::to_string(id) + " has a non-finite pose";
  }
  if (const std::string e = MatchGrid::check(GridView::of(grid)); !e.empty()) {
    ++counts_.submaps_rejected;
    return "submap " + std::to_string(id) + ": " + e;
  }
  auto& mine = impl_->robots[static_cast<std::size_t>(robot)];
  if (mine.count(id)) return "";  // a repeat (e.g. re-sent): the first copy stands
  ++counts_.submaps;
  const auto start = std::chrono::steady_clock::now();

  Submap s;
  s.id = id;
  s.pose = pose;
  const double half_w = 0.5 * grid.width * grid.resolution;
  const double half_h = 0.5 * grid.height * grid.resolution;
  s.centre = grid.origin * Eigen::Vector2d(half_w, half_h);
  s.half_extent = std::max(half_w, half_h);
  s.radius = std::hypot(half_w, half_h);
  const OccupancyMap coarse_cells = coarsen(grid, o.coarse_factor);
  s.coarse = impl_->coarse.precompute(GridView::of(coarse_cells));

  // Patches every patch_spacing metres along the trajectory, the first half a spacing in.
  std::vector<Patch> patches;
  {
    double travelled = 0, next = 0.5 * o.patch_spacing;
    const SubmapTrajectoryPose* previous = nullptr;
    for (const auto& p : trajectory) {
      if (!p.pose.isFinite()) continue;
      if (previous) travelled += (p.pose.translation() - previous->pose.translation()).norm();
      previous = &p;
      if (travelled + 1e-9 < next) continue;
      next += o.patch_spacing;
      patches.push_back({p.pose, p.stamp_ns, {}, {}});
    }
  }
  const double coarse_res = grid.resolution * o.coarse_factor;
  for (auto& patch : patches) {
    const Pose2 inverse = patch.pose.inverse();
    for (int row = 0; row < grid.height; ++row)
      for (int col = 0; col < grid.width; ++col) {
        if (grid.at(col, row) < o.occupied_percent) continue;
        const Eigen::Vector2d p = inverse * grid.cellCenter(col, row);
        if (p.norm() <= o.patch_radius) patch.fine.push_back(p);
      }
    if (patch.fine.size() > static_cast<std::size_t>(o.max_patch_points)) {
      std::vector<Eigen::Vector2d> thinned;
      const double step = static_cast<double>(patch.fine.size()) / o.max_patch_points;
      for (int k = 0; k < o.max_patch_points; ++k)
        thinned.push_back(patch.fine[static_cast<std::size_t>(k * step)]);
      patch.fine = std::move(thinned);
    }
    std::set<std::pair<long, long>> seen;
    for (const auto& p : patch.fine) {
      const auto cell = std::make_pair(std::lround(std::floor(p.x() / coarse_res)),
                                       std::lround(std::floor(p.y() / coarse_res)));
      if (seen.insert(cell).second)
        patch.coarse.emplace_back((cell.first + 0.5) * coarse_res,
                                  (cell.second + 0.5) * coarse_res);
    }
  }
  std::erase_if(patches, [&](const Patch& p) {
    const bool sparse = p.fine.size() < static_cast<std::size_t>(o.min_patch_points);
    if (sparse) ++counts_.patches_sparse;
    return sparse;
  });
  counts_.patches += patches.size();

  impl_->assembler.setSubmap(keyOf(robot, id), std::move(grid));
  mine.emplace(id, std::move(s));
  const Submap& self = mine.at(id);

  // Accepts a verified match as a closure of its pair, or keeps it as a candidate until enough
  // others agree (see the header).
  auto consider = [&](InterRobotClosure c) {
    const int lo = std::min(c.robot_a, c.robot_b), hi = std::max(c.robot_a, c.robot_b);
    PairState& pair = impl_->pairs[{lo, hi}];
    const auto oriented = [&](const InterRobotClosure& x) {
      const Pose2 e = estimate(x);
      return x.robot_a == lo ? e : e.inverse();
    };
    const Pose2 mine_estimate = oriented(c);
    const auto known = relativeFrame(lo, hi);
    if (known) {
      if (!agree(*known, mine_estimate, o) && c.global) {
        ++counts_.disagreeing;
        return;
      }
      pair.joined = true;
      pair.closures.push_back(closures_.size());
      closures_.push_back(c);
      ++counts_.closures;
      return;
    }
    ++counts_.candidates;
    std::vector<std::size_t> agreeing;
    std::set<std::tuple<int, int, std::int64_t>> patches_seen{
        {c.robot_b, c.submap_b, c.patch_stamp_ns}};
    for (std::size_t k = 0; k < pair.candidates.size(); ++k) {
      const auto& x = pair.candidates[k];
      if (!patches_seen.insert({x.robot_b, x.submap_b, x.patch_stamp_ns}).second) continue;
      if (agree(oriented(x), mine_estimate, o)) agreeing.push_back(k);
    }
    if (static_cast<int>(agreeing.size()) + 1 < o.min_agreeing) {
      pair.candidates.push_back(std::move(c));
      return;
    }
    pair.joined = true;
    ++counts_.joins;
    for (const std::size_t k : agreeing) {
      pair.closures.push_back(closures_.size());
      closures_.push_back(pair.candidates[k]);
      ++counts_.closures;
    }
    pair.closures.push_back(closures_.size());
    closures_.push_back(std::move(c));
    ++counts_.closures;
    for (auto k = agreeing.rbegin(); k != agreeing.rend(); ++k)
      pair.candidates.erase(pair.candidates.begin() + static_cast<std::ptrdiff_t>(*k));
  };

  auto refineAndVerify = [&](int other, const Submap& t, const Patch& patch, const Pose2& initial,
                             const SearchWindow& window, bool global) {
    const MatchGrid& pyramid = impl_->finePyramid(other, t.id);
    const auto result = impl_->fine.match(pyramid, patch.fine, initial, window);
    const Eigen::Vector3d sigma(window.linear / 3, window.linear / 3,
                                std::max(window.angular, 1e-3) / 3);
    const auto verdict =
        impl_->verifier.verify(result, initial, Eigen::Matrix3d(sigma.cwiseAbs2().asDiagonal()));
    if (!verdict.accepted) {
      ++(global ? counts_.refined_rejected : counts_.joined_rejected);
      return;
    }
    if (global) {
      // Overlay the two whole submaps at the match (pose of s's origin in t's frame).
      const Pose2 s_in_t = result.pose * patch.pose.inverse();
      const auto a = impl_->assembler.grid(keyOf(robot, id));
      const auto b = impl_->assembler.grid(keyOf(other, t.id));
      const auto [agree_ab, conflict_ab] =
          conflicts(*a, *b, s_in_t, o.occupied_percent, o.free_percent);
      const auto [agree_ba, conflict_ba] =
          conflicts(*b, *a, s_in_t.inverse(), o.occupied_percent, o.free_percent);
      const double total = static_cast<double>(agree_ab + conflict_ab + agree_ba + conflict_ba);
      const double fraction = total > 0 ? (conflict_ab + conflict_ba) / total : 1.0;
      if (fraction > o.max_conflict_fraction) {
        ++counts_.conflicting;
        return;
      }
    }
    InterRobotClosure c;
    c.robot_a = other;
    c.submap_a = t.id;
    c.robot_b = robot;
    c.submap_b = id;
    c.patch = patch.pose;
    c.patch_stamp_ns = patch.stamp_ns;
    c.match = result.pose;
    c.covariance = result.covariance;
    c.score = result.score;
    c.global = global;
    consider(std::move(c));
  };

  for (int other = 0; other < robots_; ++other) {
    if (other == robot) continue;
    const auto& theirs = impl_->robots[static_cast<std::size_t>(other)];
    if (theirs.empty()) continue;
    if (const auto rel = relativeFrame(other, robot)) {
      // Joined: search where the frames put each patch.
      for (const auto& patch : patches) {
        const Pose2 predicted = *rel * self.pose * patch.pose;  // in the other robot's frame
        std::vector<std::pair<double, const Submap*>> near;
        for (const auto& [tid, t] : theirs) {
          const Pose2 local = t.pose.inverse() * predicted;
          const double d = (local.translation() - t.centre).norm();
          if (d <= t.radius) near.emplace_back(d, &t);
        }
        std::sort(near.begin(), near.end(),
                  [](const auto& x, const auto& y) { return x.first < y.first; });
        if (near.size() > static_cast<std::size_t>(o.joined_candidates))
          near.resize(static_cast<std::size_t>(o.joined_candidates));
        for (const auto& [d, t] : near) {
          // Only the patch's points that fall where t has seen something: the rest would score
          // as unknown and sink a true match of a patch that reaches past t's edge.
          const Pose2 initial = t->pose.inverse() * predicted;
          const MatchGrid& pyramid = impl_->finePyramid(other, t->id);
          const Pose2 to_cells = pyramid.origin().inverse() * initial;
          Patch seen{patch.pose, patch.stamp_ns, {}, {}};
          for (const auto& p : patch.fine) {
            const Eigen::Vector2d c = (to_cells * p) / pyramid.resolution();
            if (pyramid.at(0, static_cast<int>(std::floor(c.x())),
                           static_cast<int>(std::floor(c.y()))) != pyramid.unknownValue())
              seen.fine.push_back(p);
          }
          if (seen.fine.size() < static_cast<std::size_t>(o.min_patch_points)) continue;
          ++counts_.joined_searches;
          refineAndVerify(other, *t, seen, initial,
                          {o.joined_window_linear, o.joined_window_angular}, false);
        }
      }
      continue;
    }
    // Not joined: every patch against every submap of the other robot, coarse, in parallel.
    struct Task {
      const Patch* patch;
      const Submap* target;
      scan_matching::CorrelativeMatchResult result;
    };
    std::vector<Task> tasks;
    for (const auto& patch : patches)
      for (const auto& [tid, t] : theirs) tasks.push_back({&patch, &t, {}});
    tbb::parallel_for(std::size_t{0}, tasks.size(), [&](std::size_t k) {
      Task& task = tasks[k];
      const Submap& t = *task.target;
      task.result =
          impl_->coarse.match(t.coarse, task.patch->coarse, Pose2(t.centre.x(), t.centre.y(), 0.0),
                              {t.half_extent, std::numbers::pi});
    });
    counts_.global_searches += tasks.size();
    for (const Task& task : tasks) {
      if (!task.result.matched()) {
        ++counts_.global_coarse_rejected;
        continue;
      }
      if (task.result.second_best_score > o.coarse_max_ambiguity * task.result.score) {
        ++counts_.global_ambiguous;
        continue;
      }
      refineAndVerify(other, *task.target, *task.patch, task.result.pose,
                      {o.refine_window_linear, o.refine_window_angular}, true);
    }
  }
  counts_.match_seconds +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return "";
}

OccupancyMap MapMerger::assemble() {
  for (int k = 0; k < robots_; ++k) {
    const auto f = frame(k);
    if (!f) continue;
    for (const auto& [id, s] : impl_->robots[static_cast<std::size_t>(k)])
      impl_->assembler.setPose(keyOf(k, id), *f * s.pose);
  }
  return impl_->assembler.assemble();
}

std::size_t MapMerger::bytes() const {
  std::size_t total = impl_->assembler.bytes();
  for (const auto& r : impl_->robots)
    for (const auto& [id, s] : r) total += s.coarse.bytes();
  for (const auto& c : impl_->cache) total += c.grid->bytes();
  return total;
}

}  // namespace tessera::laser_slam
