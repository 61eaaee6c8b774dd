// `tessera goal X Y THETA`: one navigation goal (msg::NavGoal) into a deployment that runs under
// `tessera launch`, and with --wait its progress (msg::NavStatus) until it ends.
//
// The command joins the deployment's shared memory as a program outside it: a Runtime of its
// own with an external publisher on the goal topic and, with --wait, one actor reading the
// status topic, wired to the other processes by ShmTransport (kExternalProcess: what it sends is
// not counted in the deployment's in-flight accounting). Topic names are the profile's global
// ones (after remaps); the launched profile lists them under `external: {inputs: [goal],
// outputs: [nav_status]}` so that they cross shared memory even with no second party inside.
#include "commands.hpp"

#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <capnp/schema.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <utility>

namespace tessera::app {

namespace {

// Exit codes besides 0 (reached; or sent, without --wait) and 2 (usage).
constexpr int kGoalEndedBadly = 1;  // failed or refused
constexpr int kNoDeployment = 3;    // nothing to send to, the deployment left, or --timeout

struct GoalArgs {
  std::string x, y, theta;  // parsed by finiteNumber(), which names the argument
  std::uint64_t id = 0;     // 0: chosen from the clock
  std::string tolerance_xy = "0", tolerance_yaw = "0";
  std::string frame = "map";
  std::string topic = "goal";
  std::string status_topic = "nav_status";
  bool wait = false;
  double timeout_s = 600;
  double connect_s = 5;
};

/// The number in `text`, or a ConfigError naming the argument. NaN never passes; infinity only
/// when `allow_inf`.
double number(const std::string& text, const std::string& name, bool allow_inf = false) {
  const char* begin = text.c_str();
  char* end = nullptr;
  const double v = std::strtod(begin, &end);
  const bool whole = !text.empty() && end == begin + text.size();
  if (!whole || std::isnan(v) || (std::isinf(v) && !allow_inf)) {
    throw ConfigError(name + ": expected a " + (allow_inf ? "" : "finite ") + "number, got '" +
                      text + "'");
  }
  return v;
}

struct Goal {
  double x = 0, y = 0, theta = 0, tolerance_xy = 0, tolerance_yaw = 0;
};

/// Checks every argument before anything touches shared memory.
Goal checkArgs(GoalArgs& a) {
  Goal g;
  g.x = number(a.x, "X");
  g.y = number(a.y, "Y");
  g.theta = number(a.theta, "THETA");
  g.tolerance_xy = number(a.tolerance_xy, "--tolerance-xy");
  g.tolerance_yaw = number(a.tolerance_yaw, "--tolerance-yaw", true);
  if (g.tolerance_xy < 0) throw ConfigError("--tolerance-xy: must be >= 0 (0: the default)");
  if (g.tolerance_yaw < 0) throw ConfigError("--tolerance-yaw: must be >= 0 (0: the default)");
  if (!(a.timeout_s > 0) || !std::isfinite(a.timeout_s))
    throw ConfigError("--timeout: must be a positive number of seconds");
  if (a.topic.empty()) throw ConfigError("--topic: empty topic name");
  if (a.status_topic.empty()) throw ConfigError("--status-topic: empty topic name");
  if (a.frame.empty()) throw ConfigError("--frame: empty frame name");
  if (a.id == 0) {
    // Unique enough across calls, and never 0 (NavStatus's "no goal").
    a.id = static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                          std::chrono::system_clock::now().time_since_epoch())
                                          .count());
  }
  return g;
}

/// The state's name in the schema (idle, planning, driving, ...).
std::string stateName(msg::NavStatus::State s) {
  const auto names = capnp::Schema::from<msg::NavStatus::State>().getEnumerants();
  const auto i = static_cast<unsigned>(s);
  return i < names.size() ? std::string(names[i].getProto().getName().cStr())
                          : "state " + std::to_string(i);
}

bool isFinal(msg::NavStatus::State s) {
  return s == msg::NavStatus::State::REACHED || s == msg::NavStatus::State::FAILED ||
         s == msg::NavStatus::State::REFUSED;
}

/// Keeps the statuses about one goal; read from the command's thread.
class StatusWatch final : public Actor {
 public:
  struct Status {
    msg::NavStatus::State state;
    std::string reason;
    double distance;
  };
  StatusWatch(std::string topic, std::uint64_t id) : topic_(std::move(topic)), id_(id) {}
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::NavStatus>(
        topic_, MailboxPolicy::keepLatest(64), [this](const Message<msg::NavStatus>& m) {
          if (m->getGoalId() != id_) return;
          std::lock_guard lock(mutex_);
          seen_.push_back({m->getState(), m->getReason(), m->getDistanceRemaining()});
        });
  }
  std::vector<Status> take() {
    std::lock_guard lock(mutex_);
    return std::exchange(seen_, {});
  }

 private:
  std::string topic_;
  std::uint64_t id_;
  std::mutex mutex_;
  std::vector<Status> seen_;
};

std::atomic<int> g_interrupted{0};
extern "C" void onGoalSignal(int) {
  g_interrupted = 1;
}

int sendGoal(GoalArgs a) {
  const Goal goal = checkArgs(a);
  // iceoryx would wait a minute for a RouDi that is not there, then abort: say so at once.
  if (!rouDiRunning()) {
    std::cerr << "error: no deployment runs on this machine (no shared-memory daemon: start one "
                 "with `tessera launch PROFILE`)\n";
    return kNoDeployment;
  }
  setIceoryxLogLevel("error");
  ShmTransportOptions so;
  so.runtime_name = "tessera_goal_" + std::to_string(::getpid());
  so.process_index = kExternalProcess;
  so.max_chunk_bytes = 64 << 10;  // a goal is ~100 bytes; a larger loan is copied, never lost
  ShmTransport transport(so);

  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 1;
  ro.show_progress = false;
  Runtime rt(ro);
  auto pub = rt.externalPublisher<msg::NavGoal>(a.topic);
  StatusWatch* watch = nullptr;
  std::vector<ShmTopic> topics(1);
  topics[0].name = a.topic;
  topics[0].type = messageTypeOf<msg::NavGoal>();
  topics[0].exported = true;
  topics[0].importing_processes = 1;  // wait for the deployment's subscriber (nothing counts)
  topics[0].any_reliable = true;      // the navigator's goal mailbox is reliable: never lost
  if (a.wait) {
    watch = &static_cast<StatusWatch&>(
        rt.add("goal_status", std::make_unique<StatusWatch>(a.status_topic, a.id)));
    ShmTopic status;
    status.name = a.status_topic;
    status.type = messageTypeOf<msg::NavStatus>();
    status.imported = true;
    status.import_policy = MailboxPolicy::keepLatest(64);  // never holds the navigator up
    topics.push_back(status);
  }
  transport.attach(rt, topics);
  rt.configure();
  rt.start();
  const auto leave = [&](int code) {
    rt.stop();
    return code;
  };
  if (!transport.waitForPublishers(
          std::chrono::milliseconds(static_cast<std::int64_t>(a.connect_s * 1000)))) {
    std::string missing;
    for (const auto& t : transport.unconnected()) missing += (missing.empty() ? "" : ", ") + t;
    std::cerr << "error: the running deployment does not take goals here: " << missing << " after "
              << a.connect_s
              << " s (is a navigator running, and does the launched profile list the topics "
                 "under external: {inputs: [...], outputs: [...]}?)\n";
    return leave(kNoDeployment);
  }

  auto loan = pub.loan();
  const auto stamp = std::chrono::duration_cast<std::chrono::nanoseconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
  setHeader(loan->initHeader(), stamp, a.frame, pub.nextSeq());
  writePose(loan->initPose(), Pose2{goal.x, goal.y, goal.theta});
  loan->setId(a.id);
  loan->setToleranceXy(goal.tolerance_xy);
  loan->setToleranceYaw(goal.tolerance_yaw);
  pub.publish(std::move(loan));
  std::cout << "goal " << a.id << " sent on '" << a.topic << "': x " << goal.x << " y " << goal.y
            << " theta " << goal.theta << " (" << a.frame << ")" << std::endl;
  if (!a.wait) return leave(0);

  auto* old_int = std::signal(SIGINT, onGoalSignal);
  auto* old_term = std::signal(SIGTERM, onGoalSignal);
  const auto restore = [&](int code) {
    std::signal(SIGINT, old_int);
    std::signal(SIGTERM, old_term);
    return leave(code);
  };
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::milliseconds(static_cast<std::int64_t>(a.timeout_s * 1000));
  std::optional<StatusWatch::Status> last;
  for (;;) {
    transport.receiveHere(std::chrono::milliseconds(100));
    for (const auto& s : watch->take()) {
      if (last && last->state == s.state && last->reason == s.reason) continue;
      last = s;
      std::cout << "goal " << a.id << ": " << stateName(s.state);
      if (!s.reason.empty()) std::cout << ": " << s.reason;
      if (s.state == msg::NavStatus::State::DRIVING && std::isfinite(s.distance))
        std::cout << " (" << std::fixed << std::setprecision(2) << s.distance << " m to go)"
                  << std::defaultfloat;
      std::cout << std::endl;
      if (isFinal(s.state)) {
        return restore(s.state == msg::NavStatus::State::REACHED ? 0 : kGoalEndedBadly);
      }
    }
    if (g_interrupted.load() != 0) {
      std::cerr << "interrupted: goal " << a.id << " is still the navigator's (not cancelled)\n";
      return restore(130);
    }
    if (!transport.unconnected().empty()) {
      std::cerr << "error: the deployment stopped publishing '" << a.status_topic
                << "' before goal " << a.id << " ended\n";
      return restore(kNoDeployment);
    }
    if (std::chrono::steady_clock::now() > deadline) {
      std::cerr << "error: goal " << a.id << ": no final state within " << a.timeout_s << " s"
                << (last ? std::string(" (last: ") + stateName(last->state) + ")"
                         : std::string(" (no status for it: is the goal in the navigator's "
                                       "frame, and its topic the one it reads?)"))
                << "\n";
      return restore(kNoDeployment);
    }
  }
}

}  // namespace

void addGoalCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand(
      "goal",
      "send a navigation goal to a running `tessera launch` deployment (--wait: follow it)");
  cmd->footer(
      "Exit: 0 reached (or sent, without --wait); 1 failed or refused; 2 usage; 3 no deployment "
      "takes the goal, it stopped, or --timeout passed.\nThe launched profile lists the topics "
      "under external: {inputs: [goal], outputs: [nav_status]}.");
  auto args = std::make_shared<GoalArgs>();
  cmd->add_option("X", args->x, "goal x in the map frame [m]")->required();
  cmd->add_option("Y", args->y, "goal y [m]")->required();
  cmd->add_option("THETA", args->theta, "goal heading [rad]")->required();
  cmd->add_option("--id", args->id, "goal id that nav_status echoes (0 or absent: from the clock)");
  cmd->add_option("--tolerance-xy", args->tolerance_xy,
                  "[m] reached when this close in position (0: the navigator's default)");
  cmd->add_option("--tolerance-yaw", args->tolerance_yaw,
                  "[rad] and this close in heading (0: the default; inf: any heading)");
  cmd->add_option("--frame", args->frame, "the goal's frame (the navigator's map frame)");
  cmd->add_option("--topic", args->topic, "global topic of the goal (after the profile's remaps)");
  cmd->add_option("--status-topic", args->status_topic, "global topic of the navigator's status");
  cmd->add_flag("--wait", args->wait, "follow the goal's status until reached, failed or refused");
  cmd->add_option("--timeout", args->timeout_s, "[s] with --wait: give up after this long");
  cmd->callback([args, &result] { result = sendGoal(*args); });
}

}  // namespace tessera::app
