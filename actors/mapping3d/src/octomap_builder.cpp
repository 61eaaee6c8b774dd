// OctoMapBuilder: octomap::OcTree insertion with our log-odds options, and the background rebuild
// that swaps a fresh tree in once every keyframe has been re-inserted at its new pose.
#include <tessera/io/atomic_file.hpp>
#include <tessera/mapping3d/octomap_builder.hpp>

#include <octomap/OcTree.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace tessera::mapping3d {

std::string_view methodName(InsertMethod m) {
  for (const auto& [name, value] : optionNames(m))
    if (value == m) return name;
  return "?";
}

void OctoMapOptions::validate() const {
  auto finite = [](double x, const char* name) {
    if (!std::isfinite(x)) throw std::invalid_argument(std::string(name) + " must be finite");
  };
  finite(resolution, "resolution");
  finite(max_range, "max_range");
  finite(log_odds_hit, "log_odds_hit");
  finite(log_odds_miss, "log_odds_miss");
  finite(log_odds_min, "log_odds_min");
  finite(log_odds_max, "log_odds_max");
  finite(log_odds_occupied, "log_odds_occupied");
  finite(downsample_leaf, "downsample_leaf");
  if (resolution <= 0) throw std::invalid_argument("resolution must be > 0");
  if (log_odds_hit <= 0) throw std::invalid_argument("log_odds_hit must be > 0");
  if (log_odds_miss >= 0) throw std::invalid_argument("log_odds_miss must be < 0");
  if (!(log_odds_min < log_odds_occupied && log_odds_occupied < log_odds_max))
    throw std::invalid_argument("log_odds_occupied must lie between log_odds_min and log_odds_max");
  if (downsample_leaf < 0) throw std::invalid_argument("downsample_leaf must be >= 0");
  if (prune_period < 1) throw std::invalid_argument("prune_period must be >= 1");
  if (rebuild_threads < 0) throw std::invalid_argument("rebuild_threads must be >= 0");
}

namespace {

// octomap takes its thresholds as probabilities and stores them as log-odds: p = 1 / (1 + e^-L).
double probability(double log_odds) {
  return 1.0 / (1.0 + std::exp(-log_odds));
}

std::shared_ptr<octomap::OcTree> makeTree(const OctoMapOptions& o) {
  auto tree = std::make_shared<octomap::OcTree>(o.resolution);
  tree->setProbHit(probability(o.log_odds_hit));
  tree->setProbMiss(probability(o.log_odds_miss));
  tree->setClampingThresMin(probability(o.log_odds_min));
  tree->setClampingThresMax(probability(o.log_odds_max));
  tree->setOccupancyThres(probability(o.log_odds_occupied));
  return tree;
}

// One cloud ready for octomap: points in the world frame and the sensor origin.
struct Scan {
  octomap::Pointcloud points;
  octomap::point3d origin;
};

Scan toScan(const PointCloud& cloud, const Eigen::Isometry3d& camera_to_world,
            const OctoMapOptions& o) {
  const PointCloud& source = cloud;
  PointCloud filtered;
  if (o.downsample_leaf > 0) filtered = voxelFilter(cloud, o.downsample_leaf);
  const auto& points = o.downsample_leaf > 0 ? filtered.points : source.points;
  const Eigen::Isometry3f t = camera_to_world.cast<float>();
  Scan scan;
  scan.points.reserve(points.size());
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    const Eigen::Vector3f w = t * p;
    scan.points.push_back(w.x(), w.y(), w.z());
  }
  const Eigen::Vector3d o3 = camera_to_world.translation();
  scan.origin = octomap::point3d(static_cast<float>(o3.x()), static_cast<float>(o3.y()),
                                 static_cast<float>(o3.z()));
  return scan;
}

// What the eager path does per voxel, for the whole tree at once: parents' occupancy, then
// merging of children that agree (without it the tree keeps every leaf and uses ~5x the memory).
void finalize(octomap::OcTree& tree) {
  tree.updateInnerOccupancy();
  tree.prune();
}

// Counts a cloud into a tree with lazy evaluation: the tree is finalized every prune_period clouds.
void countCloud(octomap::OcTree& tree, const OctoMapOptions& o, int* unfinalized) {
  if (o.lazy_eval && ++*unfinalized >= o.prune_period) {
    finalize(tree);
    *unfinalized = 0;
  }
}

// Inserts a scan; with lazy evaluation `*unfinalized` counts the clouds since the tree was last
// finalized.
void insertScan(octomap::OcTree& tree, const Scan& scan, const OctoMapOptions& o,
                int* unfinalized) {
  const double range = o.max_range > 0 ? o.max_range : -1.0;
  switch (o.method) {
    case InsertMethod::kPointCloud:
      tree.insertPointCloud(scan.points, scan.origin, range, o.lazy_eval, false);
      break;
    case InsertMethod::kDiscretized:
      tree.insertPointCloud(scan.points, scan.origin, range, o.lazy_eval, true);
      break;
    case InsertMethod::kRays:
      tree.insertPointCloudRays(scan.points, scan.origin, range, o.lazy_eval);
      break;
  }
  countCloud(tree, o, unfinalized);
}

// The voxels one cloud updates, computed apart from the tree they go into (ray casting is most
// of an insertion's time, and this part is independent per cloud).
struct CloudUpdate {
  std::size_t index = 0;  // of the keyframe
  Scan scan;              // kept for the rays method, which updates per ray and cannot be split
  octomap::KeySet free, occupied;
};

// Fills `u.free` / `u.occupied` exactly as insertPointCloud does before it updates the tree.
// `scratch` is any tree of the same resolution: octomap's ray buffers live in the tree, so each
// thread has its own.
void computeUpdate(octomap::OcTree& scratch, CloudUpdate& u, const OctoMapOptions& o) {
  const double range = o.max_range > 0 ? o.max_range : -1.0;
  if (o.method == InsertMethod::kPointCloud)
    scratch.computeUpdate(u.scan.points, u.scan.origin, u.free, u.occupied, range);
  else if (o.method == InsertMethod::kDiscretized)
    scratch.computeDiscreteUpdate(u.scan.points, u.scan.origin, u.free, u.occupied, range);
}

// The second half of insertPointCloud: free voxels, then occupied ones, each once.
void applyUpdate(octomap::OcTree& tree, const CloudUpdate& u, const OctoMapOptions& o,
                 int* unfinalized) {
  if (o.method == InsertMethod::kRays) return insertScan(tree, u.scan, o, unfinalized);
  for (const auto& key : u.free) tree.updateNode(key, false, o.lazy_eval);
  for (const auto& key : u.occupied) tree.updateNode(key, true, o.lazy_eval);
  countCloud(tree, o, unfinalized);
}

}  // namespace

struct OctoMapBuilder::State {
  mutable std::mutex mutex;
  std::condition_variable changed;
  std::shared_ptr<octomap::OcTree> tree;  // served; replaced whole by a finished rebuild
  std::size_t clouds = 0, points = 0, rebuilds = 0;
  std::uint64_t revision = 0;  // counts the changes of the served tree
  int unfinalized = 0;         // clouds in `tree` since its inner nodes were last updated

  // Inner nodes up to date before anything reads the tree as a whole (stats, files).
  void finalizeServed() {
    if (unfinalized > 0) {
      finalize(*tree);
      unfinalized = 0;
    }
  }

  // Rebuild: the latest request not yet taken by the worker (a newer one replaces it), whether
  // the worker is building, and the scans inserted since the request being built and since the
  // pending one were made (applied to the fresh tree before the swap). While a waitForRebuild
  // waits (`finishing` > 0) the worker abandons a build that a pending request has made stale.
  std::optional<std::vector<PlacedCloud>> request;
  bool building = false, stop = false;
  int finishing = 0;
  std::vector<Scan> since_building, since_pending;
  std::size_t abandoned = 0;
  std::thread worker;

  void work(const OctoMapOptions& o);
  // Builds a fresh tree of `keyframes` (a pipeline: clouds transformed and ray-cast in parallel,
  // applied to the tree in order, so the tree is the one sequential insertion gives). Returns
  // null when abandoned (stop, or finishing with a newer request pending).
  std::shared_ptr<octomap::OcTree> build(const std::vector<PlacedCloud>& keyframes,
                                         const OctoMapOptions& o, std::size_t* points,
                                         int* unfinalized);
  bool abandon() {
    std::lock_guard check(mutex);
    return stop || (finishing > 0 && request.has_value());
  }
};

std::shared_ptr<octomap::OcTree> OctoMapBuilder::State::build(
    const std::vector<PlacedCloud>& keyframes, const OctoMapOptions& o, std::size_t* points,
    int* unfinalized) {
  auto fresh = makeTree(o);
  // In the background a rebuild shares the machine with the run; one that a caller waits for
  // (waitForRebuild) has it to itself.
  const int all = tbb::this_task_arena::max_concurrency();
  bool waited_for = false;
  {
    std::lock_guard check(mutex);
    waited_for = finishing > 0;
  }
  const int threads = waited_for || o.rebuild_threads <= 0 ? all : std::min(o.rebuild_threads, all);
  tbb::task_arena arena(threads);
  tbb::enumerable_thread_specific<std::shared_ptr<octomap::OcTree>> scratch(
      [&] { return makeTree(o); });
  std::size_t next = 0;  // the input stage stops early only when the build is abandoned
  arena.execute([&] {
    tbb::parallel_pipeline(
        static_cast<std::size_t>(2 * threads),
        tbb::make_filter<void, std::shared_ptr<CloudUpdate>>(
            tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) -> std::shared_ptr<CloudUpdate> {
              if (next == keyframes.size() || abandon()) {
                fc.stop();
                return nullptr;
              }
              auto u = std::make_shared<CloudUpdate>();
              u->index = next++;
              return u;
            }) &
            tbb::make_filter<std::shared_ptr<CloudUpdate>, std::shared_ptr<CloudUpdate>>(
                tbb::filter_mode::parallel,
                [&](std::shared_ptr<CloudUpdate> u) {
                  const auto& k = keyframes[u->index];
                  u->scan = toScan(*k.cloud, k.camera_to_world, o);
                  computeUpdate(*scratch.local(), *u, o);
                  return u;
                }) &
            tbb::make_filter<std::shared_ptr<CloudUpdate>, void>(
                tbb::filter_mode::serial_in_order, [&](std::shared_ptr<CloudUpdate> u) {
                  applyUpdate(*fresh, *u, o, unfinalized);
                  *points += u->scan.points.size();
                }));
  });
  return next == keyframes.size() ? fresh : nullptr;
}

void OctoMapBuilder::State::work(const OctoMapOptions& o) {
  std::unique_lock lock(mutex);
  for (;;) {
    changed.wait(lock, [&] { return stop || request.has_value(); });
    if (stop) return;
    std::vector<PlacedCloud> keyframes = std::move(*request);
    request.reset();
    since_building = std::move(since_pending);
    since_pending.clear();
    building = true;
    lock.unlock();

    std::size_t fresh_points = 0;
    int fresh_unfinalized = 0;
    auto fresh = build(keyframes, o, &fresh_points, &fresh_unfinalized);

    lock.lock();
    if (fresh && !stop) {
      // Clouds inserted into the old tree while this one was built: the swap must not lose them.
      for (const auto& scan : since_building) {
        insertScan(*fresh, scan, o, &fresh_unfinalized);
        fresh_points += scan.points.size();
      }
      unfinalized = fresh_unfinalized;
      clouds = keyframes.size() + since_building.size();
      points = fresh_points;
      tree = std::move(fresh);
      ++rebuilds;
      ++revision;
    } else if (!stop) {
      ++abandoned;
    }
    since_building.clear();
    building = false;
    changed.notify_all();
  }
}

OctoMapBuilder::OctoMapBuilder(const OctoMapOptions& options)
    : options_(options), state_(std::make_unique<State>()) {
  options_.validate();
  state_->tree = makeTree(options_);
}

OctoMapBuilder::~OctoMapBuilder() {
  {
    std::lock_guard lock(state_->mutex);
    state_->stop = true;
  }
  state_->changed.notify_all();
  if (state_->worker.joinable()) state_->worker.join();
}

void OctoMapBuilder::insert(const PointCloud& cloud, const Eigen::Isometry3d& camera_to_world) {
  checkPose(camera_to_world, "pose");
  Scan scan = toScan(cloud, camera_to_world, options_);
  std::lock_guard lock(state_->mutex);
  insertScan(*state_->tree, scan, options_, &state_->unfinalized);
  ++state_->clouds;
  ++state_->revision;
  state_->points += scan.points.size();
  if (state_->request) state_->since_pending.push_back(scan);
  if (state_->building) state_->since_building.push_back(std::move(scan));
}

void OctoMapBuilder::rebuild(std::vector<PlacedCloud> keyframes) {
  for (const auto& k : keyframes) {
    checkPose(k.camera_to_world, "pose");
    if (!k.cloud) throw std::invalid_argument("cloud: null");
  }
  {
    std::lock_guard lock(state_->mutex);
    // Replaces a pending request; a running build goes on (the map follows at the pace of
    // rebuilds) unless waitForRebuild abandons it. This snapshot holds every cloud so far.
    state_->request = std::move(keyframes);
    state_->since_pending.clear();
    if (!state_->worker.joinable())
      state_->worker = std::thread([this] { state_->work(options_); });
  }
  state_->changed.notify_all();
}

bool OctoMapBuilder::rebuilding() const {
  std::lock_guard lock(state_->mutex);
  return state_->request.has_value() || state_->building;
}

void OctoMapBuilder::waitForRebuild() {
  std::unique_lock lock(state_->mutex);
  ++state_->finishing;  // a build made stale by a pending request is abandoned
  state_->changed.wait(lock, [&] { return !state_->request && !state_->building; });
  --state_->finishing;
}

std::optional<double> OctoMapBuilder::logOdds(const Eigen::Vector3d& point) const {
  std::lock_guard lock(state_->mutex);
  const octomap::OcTreeNode* node = state_->tree->search(point.x(), point.y(), point.z());
  if (node == nullptr) return std::nullopt;
  return node->getLogOdds();
}

Occupancy OctoMapBuilder::occupancy(const Eigen::Vector3d& point) const {
  const auto l = logOdds(point);
  if (!l) return Occupancy::kUnknown;
  return *l >= options_.log_odds_occupied ? Occupancy::kOccupied : Occupancy::kFree;
}

OctoMapStats OctoMapBuilder::stats() const {
  std::lock_guard lock(state_->mutex);
  state_->finalizeServed();
  OctoMapStats s;
  const auto& tree = *state_->tree;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    ++s.leaves;
    if (tree.isNodeOccupied(*it))
      ++s.occupied_leaves;
    else
      ++s.free_leaves;
  }
  s.memory_bytes = tree.memoryUsage();
  s.clouds_inserted = state_->clouds;
  s.points_inserted = state_->points;
  s.rebuilds_completed = state_->rebuilds;
  s.rebuilds_abandoned = state_->abandoned;
  return s;
}

std::uint64_t OctoMapBuilder::revision() const {
  std::lock_guard lock(state_->mutex);
  return state_->revision;
}

namespace {

// The centres of `tree`'s occupied nodes at `depth` (a pruned leaf above it as the nodes it
// covers there) into `out`; false, as soon as there are more than `max_points`.
bool occupiedAt(const octomap::OcTree& tree, unsigned depth, std::size_t max_points,
                std::vector<Eigen::Vector3f>& out) {
  out.clear();
  for (auto it = tree.begin_leafs(static_cast<unsigned char>(depth)), end = tree.end_leafs();
       it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const octomap::point3d c = it.getCoordinate();
    const unsigned above = depth - it.getDepth();  // > 0 for a pruned leaf
    if (above == 0) {
      if (out.size() == max_points) return false;
      out.emplace_back(c.x(), c.y(), c.z());
      continue;
    }
    const std::size_t n = std::size_t{1} << above;  // voxels per axis
    if (n * n * n > max_points - out.size()) return false;
    const double edge = it.getSize() / static_cast<double>(n);
    const Eigen::Vector3d corner =
        Eigen::Vector3d(c.x(), c.y(), c.z()) - Eigen::Vector3d::Constant(0.5 * it.getSize());
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        for (std::size_t k = 0; k < n; ++k)
          out.push_back(
              (corner + edge * (Eigen::Vector3d(static_cast<double>(i), static_cast<double>(j),
                                                static_cast<double>(k)) +
                                Eigen::Vector3d::Constant(0.5)))
                  .cast<float>());
  }
  return true;
}

}  // namespace

OccupiedVoxels OctoMapBuilder::occupiedVoxels(std::size_t max_points) const {
  std::lock_guard lock(state_->mutex);
  const octomap::OcTree& tree = *state_->tree;
  OccupiedVoxels out;
  out.revision = state_->revision;
  out.depth = static_cast<int>(tree.getTreeDepth());
  out.voxel_size = tree.getResolution();
  if (max_points == 0 || tree.getRoot() == nullptr) return out;
  // The leaves hold their own log-odds: only coarser depths need the inner nodes up to date
  // (their children's maximum), which with lazy evaluation they may not be yet.
  if (occupiedAt(tree, tree.getTreeDepth(), max_points, out.centres)) return out;
  state_->finalizeServed();
  // Depth 0 is not a depth limit for octomap's iterators (it means "the leaves"): the root, the
  // one voxel of depth 0, is taken by hand.
  for (unsigned d = tree.getTreeDepth() - 1; d >= 1; --d)
    if (occupiedAt(tree, d, max_points, out.centres)) {
      out.depth = static_cast<int>(d);
      out.voxel_size = tree.getNodeSize(d);
      return out;
    }
  out.centres.clear();
  out.depth = 0;
  out.voxel_size = tree.getNodeSize(0);
  if (tree.isNodeOccupied(tree.getRoot())) out.centres.emplace_back(0.0f, 0.0f, 0.0f);
  return out;
}

void OctoMapBuilder::writeBinary(const std::filesystem::path& file) const {
  std::lock_guard lock(state_->mutex);
  state_->finalizeServed();
  // Written to a temporary name (extension kept) and renamed into place when complete.
  io::replaceFileAtomically(file, [&](const std::filesystem::path& temp) {
    if (!state_->tree->writeBinaryConst(temp.string()))
      throw std::runtime_error(file.string() + ": writing the OctoMap failed");
  });
}

void OctoMapBuilder::readBinary(const std::filesystem::path& file) {
  auto tree = makeTree(options_);
  if (!tree->readBinary(file.string()))
    throw std::runtime_error(file.string() + ": not a readable OctoMap binary file");
  if (std::abs(tree->getResolution() - options_.resolution) > 1e-9)
    throw std::runtime_error(file.string() + ": resolution " +
                             std::to_string(tree->getResolution()) + " is not the map's " +
                             std::to_string(options_.resolution));
  waitForRebuild();
  std::lock_guard lock(state_->mutex);
  state_->tree = std::move(tree);
  state_->unfinalized = 0;
  state_->clouds = 0;
  state_->points = 0;
  ++state_->revision;
}

}  // namespace tessera::mapping3d
