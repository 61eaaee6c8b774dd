// `tessera emulate scip|sick|vectornav|create`: an emulated Hokuyo URG-04LX
// (drivers/scip_device.hpp) on a pseudo-terminal or a TCP port, streaming a recorded URG log or a
// fixed room, or an emulated SICK LMS200, VectorNav VN-100 or iRobot Create 2 on a
// pseudo-terminal (`emulate kinect`, a recording, is in cmd_emulate_kinect.cpp), so the drivers and
// whole profiles can be tried without the lasers (docs/architecture.md#device-drivers). Runs until
// SIGINT/SIGTERM, or with --exit-at-end until the log has been streamed. Exit codes: 0 ok; 2 usage
// errors; 1 a log that cannot be read.
#include "commands.hpp"

#include <tessera/datasets/urg_log.hpp>
#include <tessera/drivers/create_device.hpp>
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/scip_device.hpp>
#include <tessera/drivers/sick_lms_device.hpp>
#include <tessera/drivers/vectornav_device.hpp>
#include <tessera/runtime/options.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <iostream>
#include <memory>
#include <mutex>
#include <numbers>
#include <thread>
#include <utility>

namespace tessera::app {

namespace {

std::atomic<bool> g_emulate_stop{false};
extern "C" void onEmulateSignal(int) {
  g_emulate_stop = true;
}

/// Returns on SIGINT or SIGTERM (the emulator's device keeps running meanwhile).
void waitForStopSignal() {
  g_emulate_stop = false;
  auto* old_int = std::signal(SIGINT, onEmulateSignal);
  auto* old_term = std::signal(SIGTERM, onEmulateSignal);
  while (!g_emulate_stop) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);
}

struct EmulateSettings {
  std::string log, link;
  int tcp_port = -1;
  int baud = 115200;
  double rate = 1.0;
  double end_time = 0;
  bool loop = false, exit_at_end = false;
  double garbage = 0, corrupt = 0;
};

/// A URG log as device scans: its readings in mm, its timestamps as the device's clock, the
/// gaps between its lines (divided by `rate`) as the scan periods.
class UrgLogSource {
 public:
  explicit UrgLogSource(const EmulateSettings& s) : s_(s) { open(); }
  std::optional<drivers::EmulatedScan> next() {
    auto current = read();
    if (!current) {
      if (!s_.loop || scans_ == 0) return std::nullopt;
      open();
      current = read();
      if (!current) return std::nullopt;
    }
    ahead_ = read();  // the next line's time is this scan's period
    drivers::EmulatedScan e;
    e.ranges_mm.reserve(current->ranges.size());
    for (const float r : current->ranges)  // the reader's +inf (0) and NaN (an error code) back
      e.ranges_mm.push_back(std::isinf(r)   ? 0u
                            : std::isnan(r) ? 1u
                                            : static_cast<std::uint32_t>(std::lround(r * 1000.0)));
    e.sensor_ms = static_cast<std::uint32_t>((current->timestamp_us / 1000) & 0xFFFFFF);
    const std::int64_t gap_us = ahead_ && ahead_->timestamp_us > current->timestamp_us
                                    ? ahead_->timestamp_us - current->timestamp_us
                                    : 100'000;
    e.period_ns = static_cast<std::int64_t>(static_cast<double>(gap_us) * 1e3 / s_.rate);
    ++scans_;
    return e;
  }

 private:
  void open() {
    reader_ = std::make_unique<datasets::UrgReader>(s_.log, datasets::UrgOptions{});
    first_us_.reset();
    ahead_.reset();
  }
  /// The next line within --end-time (the one read ahead first).
  std::optional<datasets::UrgScan> read() {
    if (ahead_) return std::exchange(ahead_, std::nullopt);
    datasets::UrgScan scan;
    if (!reader_->next(scan)) return std::nullopt;
    if (!first_us_) first_us_ = scan.timestamp_us;
    if (s_.end_time > 0 && static_cast<double>(scan.timestamp_us - *first_us_) * 1e-6 > s_.end_time)
      return std::nullopt;
    return scan;
  }
  EmulateSettings s_;
  std::unique_ptr<datasets::UrgReader> reader_;
  std::optional<std::int64_t> first_us_;
  std::optional<datasets::UrgScan> ahead_;
  std::int64_t scans_ = 0;
};

/// A 6 x 4 m room seen from 1 m off its centre: a fixed scan for trying the driver.
drivers::EmulatedScan roomScan(const drivers::scip::SensorParameters& p) {
  drivers::EmulatedScan e;
  for (int step = p.first_step; step <= p.last_step; ++step) {
    const double a = (step - p.front_step) * 2 * std::numbers::pi / p.steps_per_revolution;
    const double c = std::cos(a), s = std::sin(a);
    double t = 1e9;
    if (c > 1e-9) t = std::min(t, 2.0 / c);    // x = +2 (3 m wall, 1 m closer)
    if (c < -1e-9) t = std::min(t, -4.0 / c);  // x = -4
    if (s > 1e-9) t = std::min(t, 2.0 / s);
    if (s < -1e-9) t = std::min(t, -2.0 / s);
    const auto mm = static_cast<std::uint32_t>(std::lround(t * 1000));
    e.ranges_mm.push_back(mm > static_cast<std::uint32_t>(p.max_range_mm) ? 0u : mm);
  }
  return e;
}

int runEmulate(const EmulateSettings& s) {
  namespace drv = tessera::drivers;
  if (!(s.rate > 0) || !std::isfinite(s.rate)) throw ConfigError("--rate must be > 0");
  if (s.garbage < 0 || s.garbage > 1 || s.corrupt < 0 || s.corrupt > 1)
    throw ConfigError("--garbage and --corrupt are probabilities in [0, 1]");
  if (s.link.empty() && s.tcp_port < 0)
    throw ConfigError("give --link PATH (a pseudo-terminal) or --tcp PORT");
  const auto params = drv::ScipDevice::urg04lx();
  std::shared_ptr<UrgLogSource> log;
  if (!s.log.empty()) log = std::make_shared<UrgLogSource>(s);
  std::atomic<bool> ended{false};
  drv::ScanSource source = [log, params, &ended]() -> std::optional<drv::EmulatedScan> {
    if (!log) return roomScan(params);
    auto scan = log->next();
    if (!scan) ended = true;
    return scan;
  };
  drv::ScipDevice device(params, source);
  device.faults().garbage_probability = s.garbage;
  device.faults().corrupt_probability = s.corrupt;
  drv::EmulatorHostOptions ho;
  ho.link = s.link;
  ho.tcp_port = s.tcp_port;
  ho.baud = s.baud;
  drv::EmulatorHost host({[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
                          [&](std::int64_t t) { return device.poll(t); },
                          [&] { return device.nextDue(); },
                          [&](std::int64_t t) { device.restart(t); },
                          {}},
                         ho);
  std::cout << "emulated " << params.model << " on " << host.devicePath()
            << (s.tcp_port < 0 ? " (" + std::to_string(s.baud) + " baud)" : std::string())
            << (log ? ", streaming " + s.log : std::string(", a fixed 6 x 4 m room")) << "\n"
            << std::flush;
  g_emulate_stop = false;
  auto* old_int = std::signal(SIGINT, onEmulateSignal);
  auto* old_term = std::signal(SIGTERM, onEmulateSignal);
  auto last_report = std::chrono::steady_clock::now();
  while (!g_emulate_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::int64_t sent = 0;
    host.withDevice([&] { sent = device.scansSent(); });
    if (std::chrono::steady_clock::now() - last_report > std::chrono::seconds(10)) {
      std::cerr << "emulate: " << sent << " scans sent, " << host.bytesIn() << " bytes in\n";
      last_report = std::chrono::steady_clock::now();
    }
    if (ended && s.exit_at_end) break;
  }
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);
  std::int64_t sent = 0;
  host.withDevice([&] { sent = device.scansSent(); });
  std::cerr << "emulate: " << sent << " scans sent" << (ended ? " (end of the log)" : "") << "\n";
  return 0;
}

struct SickSettings {
  std::string link;
  double garbage = 0, corrupt = 0;
};

/// The LMS's view of the same 6 x 4 m room: beams from the right, counter-clockwise.
std::vector<std::uint32_t> lmsRoom(int angle_deg, int resolution_centideg) {
  const int n = angle_deg * 100 / resolution_centideg + 1;
  std::vector<std::uint32_t> mm(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double a = (-angle_deg / 2.0 + k * resolution_centideg * 0.01) * std::numbers::pi / 180;
    const double c = std::cos(a), s = std::sin(a);
    double t = 1e9;
    if (c > 1e-9) t = std::min(t, 2.0 / c);
    if (s > 1e-9) t = std::min(t, 2.0 / s);
    if (s < -1e-9) t = std::min(t, -2.0 / s);
    mm[static_cast<std::size_t>(k)] =
        t > 8.0 ? 0u : static_cast<std::uint32_t>(std::lround(t * 1000));
  }
  return mm;
}

int runEmulateSick(const SickSettings& s) {
  namespace drv = tessera::drivers;
  if (s.garbage < 0 || s.garbage > 1 || s.corrupt < 0 || s.corrupt > 1)
    throw ConfigError("--garbage and --corrupt are probabilities in [0, 1]");
  drv::SickLmsDevice device(lmsRoom);
  device.faults().garbage_probability = s.garbage;
  device.faults().corrupt_probability = s.corrupt;
  drv::EmulatorHostOptions ho;
  ho.link = s.link;
  ho.baud = 9600;
  drv::EmulatorHost host(
      {[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
       [&](std::int64_t t) { return device.poll(t); }, [&] { return device.nextDue(); },
       [&](std::int64_t t) { device.restart(t); }, [&] { return device.baud(); }},
      ho);
  std::cout << "emulated SICK LMS200 on " << host.devicePath()
            << " (9600 baud at power-up), a fixed 6 x 4 m room\n"
            << std::flush;
  waitForStopSignal();
  std::int64_t sent = 0, skipped = 0;
  int baud = 0;
  host.withDevice([&] {
    sent = device.scansSent();
    skipped = device.scansSkipped();
    baud = device.baud();
  });
  std::cerr << "emulate: " << sent << " scans sent, " << skipped
            << " skipped (the line too slow), at " << baud << " baud\n";
  return 0;
}

}  // namespace

namespace emulate_vectornav {

struct Settings {
  std::string link;
  int baud = 115200;
  double yaw_rate = 0.2, gyro_noise = 0, accel_noise = 0;
  double garbage = 0, corrupt = 0;
};

/// The emulated VN-100 on a pseudo-terminal, turning left at a constant rate, level.
int run(const Settings& s) {
  namespace drv = tessera::drivers;
  if (s.garbage < 0 || s.garbage > 1 || s.corrupt < 0 || s.corrupt > 1)
    throw ConfigError("--garbage and --corrupt are probabilities in [0, 1]");
  if (!std::isfinite(s.yaw_rate) || !(s.gyro_noise >= 0) || !(s.accel_noise >= 0))
    throw ConfigError("--yaw-rate must be finite, --gyro-noise and --accel-noise >= 0");
  drv::VectorNavDevice device(s.baud);
  device.motion().angular_velocity = {0, 0, s.yaw_rate};
  device.motion().gyro_noise = s.gyro_noise;
  device.motion().accel_noise = s.accel_noise;
  device.faults().garbage_probability = s.garbage;
  device.faults().corrupt_probability = s.corrupt;
  drv::EmulatorHostOptions ho;
  ho.link = s.link;
  ho.baud = s.baud;
  drv::EmulatorHost host(
      {[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
       [&](std::int64_t t) { return device.poll(t); }, [&] { return device.nextDue(); },
       [&](std::int64_t t) { device.restart(t); }, [&] { return device.baud(); }},
      ho);
  std::cout << "emulated VectorNav " << drv::VectorNavDevice::kModel << " on " << host.devicePath()
            << " (" << s.baud << " baud at power-up, VNYMR at 40 Hz), turning left at "
            << s.yaw_rate << " rad/s\n"
            << std::flush;
  waitForStopSignal();
  std::int64_t sent = 0, skipped = 0;
  int baud = 0, type = 0, rate = 0;
  host.withDevice([&] {
    sent = device.linesSent();
    skipped = device.linesSkipped();
    baud = device.baud();
    type = device.outputType();
    rate = device.outputRate();
  });
  std::cerr << "emulate: " << sent << " lines sent, " << skipped
            << " skipped (the line too slow), output type " << type << " at " << rate << " Hz, "
            << baud << " baud\n";
  return 0;
}

}  // namespace emulate_vectornav

namespace emulate_create {

struct Settings {
  std::string link;
  double garbage = 0, corrupt = 0;
};

/// The emulated Create 2 on a pseudo-terminal: a robot on an open floor, its battery charged.
int run(const Settings& s) {
  namespace drv = tessera::drivers;
  if (s.garbage < 0 || s.garbage > 1 || s.corrupt < 0 || s.corrupt > 1)
    throw ConfigError("--garbage and --corrupt are probabilities in [0, 1]");
  drv::CreateDevice device;
  device.faults().garbage_probability = s.garbage;
  device.faults().corrupt_probability = s.corrupt;
  drv::EmulatorHostOptions ho;
  ho.link = s.link;
  ho.baud = 115200;
  drv::EmulatorHost host({[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
                          [&](std::int64_t t) { return device.poll(t); },
                          [&] { return device.nextDue(); },
                          [&](std::int64_t t) { device.restart(t); },
                          {}},
                         ho);
  std::cout << "emulated iRobot Create 2 on " << host.devicePath()
            << " (115200 baud, Open Interface), on an open floor\n"
            << std::flush;
  waitForStopSignal();
  double left = 0, right = 0;
  host.withDevice([&] {
    left = device.leftDistance();
    right = device.rightDistance();
  });
  std::cerr << "emulate: the wheels rolled " << left << " m (left) and " << right << " m (right)\n";
  return 0;
}

}  // namespace emulate_create

void addEmulateCommand(CLI::App& app, int& result) {
  auto* emulate = app.add_subcommand("emulate", "emulated devices for trying drivers without them");
  emulate->require_subcommand(1);
  auto s = std::make_shared<EmulateSettings>();
  auto* scip = emulate->add_subcommand(
      "scip", "a Hokuyo URG-04LX speaking SCIP 2.0 on a pseudo-terminal or TCP port");
  scip->add_option("--log", s->log, "URG log to stream (exp2.dat.gz); default a fixed room")
      ->check(CLI::ExistingFile);
  scip->add_option("--link", s->link,
                   "create this symlink to the pseudo-terminal (the device "
                   "path to give the driver)");
  scip->add_option("--tcp", s->tcp_port, "listen on 127.0.0.1:PORT instead (0: any free port)")
      ->check(CLI::Range(0, 65535));
  scip->add_option("--baud", s->baud,
                   "the device's baud rate; a driver at another one hears noise");
  scip->add_option("--rate", s->rate, "replay speed of the log (1 = as recorded)");
  scip->add_option("--end-time", s->end_time, "stop the log this many seconds after its start");
  scip->add_flag("--loop", s->loop, "start the log again at its end");
  scip->add_flag("--exit-at-end", s->exit_at_end, "exit once the log has been streamed");
  scip->add_option("--garbage", s->garbage, "probability of noise bytes before a reply");
  scip->add_option("--corrupt", s->corrupt, "probability of a corrupted byte in a reply");
  scip->callback([s, &result] { result = runEmulate(*s); });

  auto v = std::make_shared<emulate_vectornav::Settings>();
  auto* vn100 = emulate->add_subcommand(
      "vectornav",
      "a VectorNav VN-100 IMU (ASCII: registers, VNYMR/VNIMU output, baud switching) on a "
      "pseudo-terminal");
  vn100->add_option("--link", v->link, "create this symlink to the pseudo-terminal")->required();
  vn100->add_option("--baud", v->baud, "its baud rate at power-up (the factory's: 115200)")
      ->check(CLI::IsMember({9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600}));
  vn100->add_option("--yaw-rate", v->yaw_rate, "[rad/s] its constant turn, counter-clockwise");
  vn100->add_option("--gyro-noise", v->gyro_noise, "[rad/s] standard deviation per sample");
  vn100->add_option("--accel-noise", v->accel_noise, "[m/s^2] standard deviation per sample");
  vn100->add_option("--garbage", v->garbage, "probability of noise bytes before a line");
  vn100->add_option("--corrupt", v->corrupt, "probability of a corrupted byte in a line");
  vn100->callback([v, &result] { result = emulate_vectornav::run(*v); });

  auto c = std::make_shared<emulate_create::Settings>();
  auto* create = emulate->add_subcommand(
      "create",
      "an iRobot Create 2 (Open Interface: drive, sensor stream with encoders, bumpers, cliffs, "
      "battery) on a pseudo-terminal");
  create->add_option("--link", c->link, "create this symlink to the pseudo-terminal")->required();
  create->add_option("--garbage", c->garbage, "probability of noise bytes before a frame");
  create->add_option("--corrupt", c->corrupt, "probability of a corrupted byte in a frame");
  create->callback([c, &result] { result = emulate_create::run(*c); });

  auto l = std::make_shared<SickSettings>();
  auto* sick = emulate->add_subcommand(
      "sick",
      "a SICK LMS200 (telegrams with CRC, baud switching to 500 kBd, 75 Hz) on a "
      "pseudo-terminal");
  sick->add_option("--link", l->link, "create this symlink to the pseudo-terminal")->required();
  sick->add_option("--garbage", l->garbage, "probability of noise bytes before a reply");
  sick->add_option("--corrupt", l->corrupt, "probability of a corrupted byte in a reply");
  sick->callback([l, &result] { result = runEmulateSick(*l); });

  addEmulateKinectCommand(*emulate, result);
}

}  // namespace tessera::app
