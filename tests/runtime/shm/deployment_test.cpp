#include <tessera/runtime/profile.hpp>
#include <tessera/shm/deployment.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <limits>
#include <memory>
#include <thread>

using namespace tessera;

namespace {
Profile simMapping(const std::vector<std::string>& sets = {}) {
  return loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_mapping.yaml", sets);
}
const ShmTopic* find(const std::vector<ShmTopic>& topics, const std::string& name) {
  auto it =
      std::find_if(topics.begin(), topics.end(), [&](const ShmTopic& t) { return t.name == name; });
  return it == topics.end() ? nullptr : &*it;
}
}  // namespace

TEST_CASE("a deployment plan exports what crosses processes and stops publishers first",
          "[deployment]") {
  const auto plan = planDeployment(simMapping());
  REQUIRE(plan.processes == std::vector<std::string>{"robot", "mapping"});
  const auto* scan_out = find(plan.topics.at("robot"), "scan");
  const auto* scan_in = find(plan.topics.at("mapping"), "scan");
  REQUIRE(scan_out != nullptr);
  REQUIRE(scan_in != nullptr);
  CHECK(scan_out->exported);
  CHECK_FALSE(scan_out->imported);
  CHECK(scan_in->imported);
  CHECK_FALSE(scan_in->exported);
  CHECK(scan_in->importing_processes == 1);
  // A topic used inside one process stays in it (the mapper's map to the map writer).
  CHECK(find(plan.topics.at("mapping"), "map") == nullptr);
  CHECK_FALSE(plan.demands.empty());
}

TEST_CASE("a deployment plan lists each route from a publishing to an importing process",
          "[deployment]") {
  const auto plan = planDeployment(simMapping());
  const auto route = std::find_if(plan.routes.begin(), plan.routes.end(),
                                  [](const DeliveryRoute& r) { return r.topic == "scan"; });
  REQUIRE(route != plan.routes.end());
  CHECK(route->from == plan.indexOf("robot"));
  CHECK(route->to == plan.indexOf("mapping"));
  for (const auto& r : plan.routes) CHECK(r.from != r.to);  // nothing loops back here
}

TEST_CASE("the delivery ledger tells loss between live processes from loss with a dead one",
          "[deployment]") {
  DeploymentPlan plan;
  plan.processes = {"robot", "mapping"};
  plan.routes = {{"scan", 0, 1, true}, {"odom", 0, 1, true}, {"pose", 1, 0, false}};
  auto ledger = std::make_unique<DeliveryLedger>();
  const RouteLedger view = routeLedger(plan, *ledger);
  const auto out = view.outgoing("scan", 0);
  REQUIRE(out.size() == 1);
  CHECK(out[0] == &ledger->routes[0]);
  CHECK(view.incoming("odom", 0, 1) == &ledger->routes[1]);
  CHECK(view.incoming("odom", 1, 0) == nullptr);
  CHECK(view.outgoing("map", 0).empty());
  ledger->routes[0].sent = 100;
  ledger->routes[0].received = 97;
  ledger->routes[0].gaps = 1;
  ledger->routes[1].sent = 50;
  ledger->routes[1].received = 51;  // a sender killed between publishing and counting
  ledger->routes[2].sent = 10;
  ledger->routes[2].received = 10;

  SECTION("nobody died: whatever was not received was lost between live processes") {
    const auto d = readDelivery(plan, *ledger, {false, false});
    REQUIRE(d.size() == 3);
    CHECK(d[0].lost_live == 3);
    CHECK(d[0].lost_with_dead == 0);
    CHECK(d[0].dead.empty());
    CHECK(d[1].lost_live == 0);
    CHECK(d[2].lost_live == 0);
  }
  SECTION("the receiver died: only the gaps it saw were lost between live processes") {
    const auto d = readDelivery(plan, *ledger, {false, true});
    CHECK(d[0].lost_live == 1);
    CHECK(d[0].lost_with_dead == 2);
    CHECK(d[0].dead == std::vector<std::string>{"mapping"});
    CHECK(d[2].dead == std::vector<std::string>{"mapping"});
  }
}

TEST_CASE("topics used from outside the deployment cross shared memory without a second party",
          "[deployment]") {
  const auto plan = planDeployment(
      loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_nav_launch.yaml"));
  REQUIRE(plan.processes == std::vector<std::string>{"robot", "nav"});
  // goal: only `tessera goal` publishes it; the navigator's process does not wait for it.
  const auto* goal = find(plan.topics.at("nav"), "goal");
  REQUIRE(goal != nullptr);
  CHECK(goal->imported);
  CHECK_FALSE(goal->exported);
  CHECK(goal->publishing_processes == 0);
  CHECK(goal->import_policy.kind == MailboxPolicy::Kind::kReliable);
  CHECK(find(plan.topics.at("robot"), "goal") == nullptr);
  // nav_status: only read outside; nothing inside counts it in flight.
  const auto* status = find(plan.topics.at("nav"), "nav_status");
  REQUIRE(status != nullptr);
  CHECK(status->exported);
  CHECK_FALSE(status->imported);
  CHECK(status->importing_processes == 0);
  // Without external: the same topics would stay inside the process.
  Profile p = loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_nav_launch.yaml");
  p.external_outputs.clear();
  CHECK(find(planDeployment(p).topics.at("nav"), "nav_status") == nullptr);
}

TEST_CASE("a host plans without the other hosts' actors whose inputs only they have",
          "[deployment]") {
  // rgbd_slam_split's player needs the robot's dataset folder, which the server does not have.
  const Profile profile =
      loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/rgbd_slam_split.yaml");
  CHECK_THROWS_WITH(planDeployment(profile),
                    Catch::Contains("path") && Catch::Contains("required"));
  const auto plan = planDeployment(profile, "server");
  REQUIRE(plan.unchecked.size() == 1);
  CHECK(plan.unchecked.count("player") == 1);
  CHECK_THAT(plan.unchecked.at("player"), Catch::Contains("path"));
  const auto* keyframes = find(plan.topics.at("server"), "keyframes");
  REQUIRE(keyframes != nullptr);
  CHECK(keyframes->imported);
  CHECK(find(plan.topics.at("server"), "camera_pose") != nullptr);
  // The robot's own actors are never left out: its plan fails on its own missing folder.
  CHECK_THROWS_WITH(planDeployment(profile, "robot"), Catch::Contains("path"));
}

TEST_CASE("a profile run in one process has nothing to share", "[deployment]") {
  const auto plan = planDeployment(
      simMapping({"sim.process=main", "mapper.process=main", "map_writer.process=main",
                  "trajectory_writer.process=main", "ground_truth_writer.process=main",
                  "odometry_writer.process=main"}));
  CHECK(plan.processes == std::vector<std::string>{"main"});
  CHECK(plan.topics.empty());
}

TEST_CASE("restart naming no process of the profile is a clear error", "[deployment]") {
  Profile p = simMapping();
  p.restart = {"mapper_typo"};
  try {
    planDeployment(p);
    FAIL("expected a ConfigError");
  } catch (const ConfigError& e) {
    CHECK_THAT(e.what(), Catch::Contains("restart names process 'mapper_typo'"));
  }
  CHECK_THROWS_WITH(
      parseProfile("restart: mapping\nactors: {sim: {type: simulator}}\n", "bad.yaml"),
      Catch::Contains("bad.yaml:1") &&
          Catch::Contains("restart: expected a list of process names"));
}

TEST_CASE("the memory pools cover every declared message bound", "[deployment]") {
  const auto pools = memPoolsFor({{300, 10}, {5u << 20, 20}});
  std::size_t largest = 0;
  for (const auto& p : pools) largest = std::max(largest, p.chunk_bytes);
  CHECK(largest >= (5u << 20));
  std::size_t total = 0;
  for (const auto& p : pools) total += p.chunk_bytes * p.count;
  CHECK(total <= (std::size_t{1} << 30));
}

namespace {
/// sim_slam_global split over robot, main and global: submaps and grids cross processes and
/// topics run both ways between them.
DeploymentPlan slamOverThreeProcesses() {
  return planDeployment(
      loadProfile(std::string(TESSERA_SOURCE_DIR) + "/apps/profiles/sim_slam_global.yaml",
                  {"sim.process=robot", "loops.process=global", "optimizer.process=global"}));
}
}  // namespace

TEST_CASE("a deployment with grids crossing processes stays within 1 GiB of shared memory",
          "[deployment]") {
  // iceoryx zeroes the whole segment when RouDi starts: every pool byte is memory and time.
  const auto plan = slamOverThreeProcesses();
  std::size_t needed = 0;
  for (const auto& d : plan.demands) needed = std::max(needed, d.max_bytes);
  REQUIRE(needed >= (std::size_t{16} << 20));  // submaps cross processes here
  const auto pools = memPoolsFor(plan.demands);
  std::size_t total = 0, largest = 0;
  for (const auto& p : pools) {
    total += p.chunk_bytes * p.count;
    largest = std::max(largest, p.chunk_bytes);
    CHECK(p.count >= 4);
  }
  CHECK(largest >= needed);
  CHECK(total <= (std::size_t{1} << 30));
}

TEST_CASE("a deployment with topics both ways between processes stops its actors in stages",
          "[deployment]") {
  // The SLAM builder in main feeds the optimiser in global, whose stop-time output feeds the
  // writers back in main: main stops its upstream actors, then global, then the rest of main.
  const auto plan = slamOverThreeProcesses();
  REQUIRE(plan.processes == std::vector<std::string>{"robot", "main", "global"});
  std::vector<std::string> order;
  std::vector<int> owners;
  for (const auto& s : plan.stop_stages) {
    owners.push_back(s.process);
    order.insert(order.end(), s.actors.begin(), s.actors.end());
  }
  CHECK(owners == std::vector<int>{0, 1, 2, 1});
  CHECK(order.size() == 10);  // every actor once
  auto at = [&](const std::string& a) {
    return std::find(order.begin(), order.end(), a) - order.begin();
  };
  CHECK(at("sim") < at("slam"));
  CHECK(at("slam") < at("optimizer"));
  CHECK(at("loops") < at("optimizer"));
  CHECK(at("optimizer") < at("final_trajectory_writer"));
  CHECK(at("optimizer") < at("assembler"));
  CHECK(at("assembler") < at("map_writer"));
}

TEST_CASE("a restarted process that leaves before it runs does not hold up the stop",
          "[deployment]") {
  // A worker restarted just before Ctrl-C finds the run already stopping and leaves without
  // running; its stop stage must be skipped, not waited for.
  const std::vector<StopStage> stages = {{0, {"sim"}}, {1, {"mapper", "map_writer"}}};
  auto block = std::make_unique<SyncBlock>();
  DeploymentClock clock(*block, 2, {0, 1}, /*sim=*/false, 0, std::numeric_limits<Nanos>::max());
  WorkerCoordinator robot(*block, 0, stages), mapping(*block, 1, stages);
  robot.slot().ready = 1;
  mapping.slot().ready = 1;
  clock.step();
  REQUIRE(block->go.load() == 1);

  std::atomic<bool> left{false};
  std::vector<std::string> mapping_stage;
  std::thread mapping_thread([&] {
    const auto not_busy = [] { return false; };
    RunCoordinator::LocalState state;
    state.next_due = std::numeric_limits<Nanos>::max();
    while (mapping.idle(state, not_busy).verdict == RunCoordinator::Verdict::kWork) {
    }
    mapping_stage = mapping.awaitStopTurn(not_busy);
    mapping.stopped();
    mapping.awaitStopTurn(not_busy);  // the turn to leave
    left = true;
  });

  // The robot is killed and restarted; the stop comes before the new one is ready.
  robot.slot().idle = 1;  // what the dead incarnation left behind
  clock.markGone(0);
  clock.markRestarted(0);
  CHECK(robot.slot().idle.load() == 0);
  WorkerCoordinator again(*block, 0, stages);
  clock.requestStop("interrupted");
  CHECK_FALSE(again.readyAndWait());
  again.slot().stopped = 1;  // what a worker does when it leaves without running
  clock.markGone(0);         // the launcher saw it exit

  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!left.load() && std::chrono::steady_clock::now() < deadline) {
    clock.step();
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  const bool stopped_in_time = left.load();
  if (!stopped_in_time) block->stop_turn = 1000;  // release the thread
  mapping_thread.join();
  CHECK(stopped_in_time);
  CHECK(mapping_stage == std::vector<std::string>{"mapper", "map_writer"});
  CHECK(clock.reason() == "interrupted");
}

TEST_CASE("a doorbell wakes its sleeper at once and a missed ring costs only the timeout",
          "[deployment]") {
  using namespace std::chrono;
  std::atomic<std::uint32_t> bell{0}, waiting{0};
  // Rung after `seen` was read: the wait returns at once.
  const std::uint32_t seen = bell.load();
  ringBell(bell, waiting);
  auto t0 = steady_clock::now();
  waitBell(bell, waiting, seen, milliseconds(500));
  CHECK(steady_clock::now() - t0 < milliseconds(100));
  // Nobody rings: it sleeps for the timeout, not for ever.
  t0 = steady_clock::now();
  waitBell(bell, waiting, bell.load(), milliseconds(30));
  const auto slept = steady_clock::now() - t0;
  CHECK(slept >= milliseconds(25));
  CHECK(slept < milliseconds(400));
  // Rung by another thread while asleep: woken long before the timeout.
  std::atomic<bool> asleep{false};
  std::thread ringer([&] {
    while (waiting.load() == 0) std::this_thread::yield();
    asleep = true;
    ringBell(bell, waiting);
  });
  t0 = steady_clock::now();
  waitBell(bell, waiting, bell.load(), seconds(5));
  ringer.join();
  CHECK(asleep.load());
  CHECK(steady_clock::now() - t0 < seconds(2));
  CHECK(waiting.load() == 0);
}
