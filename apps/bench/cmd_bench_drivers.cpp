// `tessera bench drivers`: the device drivers at their devices' full rates against the
// emulated devices (on a pseudo-terminal or TCP; the Kinect through fakenect): how long a scan
// takes from its last byte read to its message published, and what CPU the driver's I/O thread
// uses.
#include "bench_commands.hpp"

#include <tessera/drivers/create_base_actor.hpp>
#include <tessera/drivers/create_device.hpp>
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/fakenect_recording.hpp>
#include <tessera/drivers/hokuyo_driver_actor.hpp>
#include <tessera/drivers/kinect_driver_actor.hpp>
#include <tessera/drivers/scip_device.hpp>
#include <tessera/drivers/sick_lms_device.hpp>
#include <tessera/drivers/sick_lms_driver_actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/runtime.hpp>

#include <nlohmann/json.hpp>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <thread>

namespace tessera::app {

namespace drivers_bench {

namespace drv = tessera::drivers;

struct Options {
  double seconds = 20;
  bool json = false;
};

struct Device {
  std::string name, link;
  drv::scip::SensorParameters params;
};

/// A UTM-30LX: 1081 steps of 1440 per turn, 40 Hz, 30 m; usually on Ethernet.
drv::scip::SensorParameters utm30lx() {
  drv::scip::SensorParameters p;
  p.model = "UTM-30LX(Hokuyo Automatic Co.,Ltd.)";
  p.min_range_mm = 23;
  p.max_range_mm = 30000;
  p.steps_per_revolution = 1440;
  p.first_step = 0;
  p.last_step = 1080;
  p.front_step = 540;
  p.scan_rpm = 2400;
  return p;
}

/// A sink for the driver's scans (the bench measures the driver, not a consumer).
class Sink final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::LaserScan>("scan", MailboxPolicy::keepLatest(8),
                                  [](const Message<msg::LaserScan>&) {});
  }
};

/// Runs `driver` against an emulated device for o.seconds on the wall clock; its figures as the
/// JSON row of `name`.
nlohmann::json measure(std::unique_ptr<Actor> driver, const std::string& name,
                       const std::string& link, double rate_hz, int beams, const Options& o) {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("laser", std::move(driver));
  rt.add("sink", std::make_unique<Sink>());
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    rt.requestStop();
  });
  const auto report = rt.run();
  stopper.join();
  const auto& s = report.actors.at(0).summary;
  const auto num = [&s](const char* key) { return std::get<double>(s.at(key)); };
  const auto count = [&s](const char* key) { return std::get<std::int64_t>(s.at(key)); };
  return {{"device", name},
          {"link", link},
          {"rate_hz", rate_hz},
          {"steps", beams},
          {"scans", count("scans_published")},
          {"bad_replies", count("bad_replies")},
          {"latency_ms_median", num("latency_ms_median")},
          {"latency_ms_p99", num("latency_ms_p99")},
          {"latency_ms_max", num("latency_ms_max")},
          {"cpu_percent", 100 * num("cpu_s") / o.seconds}};
}

/// A latency figure for the table ("-" where there is none).
std::string ms(const nlohmann::json& v) {
  if (v.is_null()) return "-";
  std::ostringstream out;
  out << std::fixed << std::setprecision(3) << v.get<double>();
  return out.str();
}

/// A room-like range profile of `n` readings [mm] that changes with every scan `k`.
std::vector<std::uint32_t> profile(std::size_t n, std::uint64_t k, std::uint32_t spread) {
  std::vector<std::uint32_t> mm(n);
  for (std::size_t i = 0; i < n; ++i)
    mm[i] = static_cast<std::uint32_t>(500 + (i * 37 + k * 11) % spread);
  return mm;
}

nlohmann::json runDevice(const Device& d, const Options& o) {
  std::uint64_t k = 0;
  const int steps = d.params.last_step - d.params.first_step + 1;
  drv::ScipDevice device(d.params, [&]() -> std::optional<drv::EmulatedScan> {
    drv::EmulatedScan s;
    s.ranges_mm = profile(static_cast<std::size_t>(steps), k++, 4000);
    return s;
  });
  drv::EmulatorHostOptions ho;
  if (d.link == "tcp") ho.tcp_port = 0;
  drv::EmulatorHost host({[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
                          [&](std::int64_t t) { return device.poll(t); },
                          [&] { return device.nextDue(); },
                          {},
                          {}},
                         ho);
  drv::HokuyoDriverOptions opts;
  opts.device = host.devicePath();
  return measure(std::make_unique<drv::HokuyoDriverActor>(opts), d.name, d.link,
                 d.params.scan_rpm / 60.0, steps, o);
}

/// The LMS200 on a pseudo-terminal: found at 9600 baud, switched to 500 kBd, 180 deg at 1 deg.
nlohmann::json runLms(const Options& o) {
  std::uint64_t k = 0;
  drv::SickLmsDevice device([&k](int angle, int res) {
    return profile(static_cast<std::size_t>(angle * 100 / res + 1), k++, 7000);
  });
  drv::EmulatorHostOptions ho;
  ho.baud = 9600;
  drv::EmulatorHost host({[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
                          [&](std::int64_t t) { return device.poll(t); },
                          [&] { return device.nextDue(); },
                          {},
                          [&] { return device.baud(); }},
                         ho);
  drv::SickLmsDriverOptions opts;
  opts.device = host.devicePath();
  opts.baud = 500000;
  return measure(std::make_unique<drv::SickLmsDriverActor>(opts), "LMS200", "pty", 75.0, 181, o);
}

/// A sink for the Kinect's frames.
class FrameSink final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::RgbdFrame>("rgbd", MailboxPolicy::keepLatest(2),
                                  [](const Message<msg::RgbdFrame>&) {});
  }
};

/// The kinect driver on libfreenect's own player (fakenect) at the Kinect's 30 Hz: a recording
/// of one still 640 x 480 scene (hard links: no disk), raw depth converted by the driver. Its
/// I/O thread also runs fakenect's reading of each frame from the page cache, where a device
/// has libusb's transfers: a figure of the same order.
nlohmann::json runKinect(const Options& o) {
  const auto folder = std::filesystem::temp_directory_path() /
                      ("tessera_bench_kinect_" + std::to_string(::getpid()));
  std::filesystem::remove_all(folder);
  drv::KinectDepthModel model;
  {
    drv::FakenectRecordingWriter w(folder);
    std::vector<std::uint16_t> depth(640 * 480);
    std::vector<std::uint8_t> color(640 * 480 * 3);
    for (std::size_t i = 0; i < depth.size(); ++i) {
      depth[i] =
          static_cast<std::uint16_t>(model.disparity(0.8 + 0.01 * static_cast<double>(i % 300)));
      color[3 * i] = static_cast<std::uint8_t>(i);
    }
    const int frames = static_cast<int>(std::lround(o.seconds * 30));
    for (int k = 0; k < frames; ++k) {
      const double t = k / 30.0;
      const auto ticks = static_cast<std::uint32_t>(std::llround(t * 60e6) & 0xffffffffLL);
      w.addDepth(t, ticks, depth);
      w.addColor(t, ticks, color);
    }
  }
  drv::KinectActorOptions opts;
  opts.recording = folder.string();
  opts.registration = "none";
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("camera", std::make_unique<drv::KinectDriverActor>(opts));
  rt.add("sink", std::make_unique<FrameSink>());
  // fakenect prints its end of playback on stdout, which carries only the JSON: on stderr.
  std::fflush(stdout);
  const int saved_stdout = ::dup(STDOUT_FILENO);
  ::dup2(STDERR_FILENO, STDOUT_FILENO);
  const auto report = rt.run();  // ends with the recording
  std::fflush(stdout);
  ::dup2(saved_stdout, STDOUT_FILENO);
  ::close(saved_stdout);
  std::filesystem::remove_all(folder);
  const auto& s = report.actors.at(0).summary;
  const auto num = [&s](const char* key) { return std::get<double>(s.at(key)); };
  const auto count = [&s](const char* key) { return std::get<std::int64_t>(s.at(key)); };
  return {{"device", "Kinect v1"},
          {"link", "fakenect"},
          {"rate_hz", 30.0},
          {"steps", 640 * 480},
          {"scans", count("frames")},
          {"bad_replies", count("dropped_unpaired")},
          {"latency_ms_median", num("latency_ms_median")},
          {"latency_ms_p99", num("latency_ms_p99")},
          {"latency_ms_max", num("latency_ms_max")},
          {"cpu_percent", 100 * num("cpu_s") / report.wall_s}};
}

/// create_base with an emulated Create 2 on a pseudo-terminal: the OI's 15 ms sensor stream.
/// No latency figure (no scan): CPU of the I/O thread only.
nlohmann::json runCreate(const Options& o) {
  drv::CreateDevice device;
  drv::EmulatorHost host({[&](std::string_view b, std::int64_t t) { device.receive(b, t); },
                          [&](std::int64_t t) { return device.poll(t); },
                          [&] { return device.nextDue(); },
                          [&](std::int64_t t) { device.restart(t); },
                          {}},
                         drv::EmulatorHostOptions{});
  drv::CreateBaseActorOptions opts;
  opts.device = host.devicePath();
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  [[maybe_unused]] auto cmd = rt.externalPublisher<msg::Twist>("base_cmd");  // nothing drives it
  rt.add("base", std::make_unique<drv::CreateBaseActor>(opts));
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    rt.requestStop();
  });
  const auto report = rt.run();
  stopper.join();
  const auto& s = report.actors.at(0).summary;
  return {{"device", "Create 2"},
          {"link", "pty"},
          {"rate_hz", 1000.0 / 15},
          {"steps", 0},
          {"scans", std::get<std::int64_t>(s.at("frames"))},
          {"bad_replies", std::get<std::int64_t>(s.at("bad_frames"))},
          {"latency_ms_median", nullptr},
          {"latency_ms_p99", nullptr},
          {"latency_ms_max", nullptr},
          {"cpu_percent", 100 * std::get<double>(s.at("cpu_s")) / o.seconds}};
}

}  // namespace drivers_bench

void addBenchDriversCommand(CLI::App& bench, int& result) {
  namespace db = drivers_bench;
  auto* cmd = bench.add_subcommand(
      "drivers",
      "device drivers at their devices' full rates against the emulated devices: hokuyo_scip "
      "with a URG-04LX on a pseudo-terminal (10 Hz, 682 steps) and a UTM-30LX on TCP (40 Hz, "
      "1081 steps), sick_lms with an LMS200 at 500 kBd (75 Hz, 181 beams), kinect through "
      "fakenect (30 Hz, 640 x 480) and create_base with a Create 2 (15 ms sensor frames); "
      "latency from a scan's last byte read (a Kinect frame handed over by libfreenect) to its "
      "message published, CPU of the driver's I/O thread. For the Kinect, steps are pixels and "
      "scans frames; for the Create, scans are sensor frames and the latencies null.\n"
      "--json prints one object: {machine, seconds, devices: [{device, link (pty | tcp), "
      "rate_hz, steps, scans, bad_replies, latency_ms_median, latency_ms_p99, latency_ms_max, "
      "cpu_percent}]}");
  auto o = std::make_shared<db::Options>();
  cmd->add_option("--seconds", o->seconds, "run time per device")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (!(o->seconds >= 1) || !std::isfinite(o->seconds))
      throw ConfigError("--seconds must be >= 1");
    const std::vector<db::Device> devices{
        {"URG-04LX", "pty", drivers::ScipDevice::urg04lx()},
        {"UTM-30LX", "tcp", db::utm30lx()},
    };
    nlohmann::json list = nlohmann::json::array();
    for (const auto& d : devices) {
      if (!o->json)
        std::cerr << "[bench drivers] " << d.name << " over " << d.link << ", " << o->seconds
                  << " s\n";
      list.push_back(db::runDevice(d, *o));
    }
    if (!o->json)
      std::cerr << "[bench drivers] LMS200 at 500 kBd over pty, " << o->seconds << " s\n";
    list.push_back(db::runLms(*o));
    if (!o->json)
      std::cerr << "[bench drivers] Kinect v1 through fakenect, " << o->seconds << " s\n";
    list.push_back(db::runKinect(*o));
    if (!o->json) std::cerr << "[bench drivers] Create 2 over pty, " << o->seconds << " s\n";
    list.push_back(db::runCreate(*o));
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"seconds", o->seconds},
                                  {"devices", list}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << std::left << std::setw(10) << "device" << std::setw(6) << "link" << std::right
              << std::setw(8) << "Hz" << std::setw(8) << "scans" << std::setw(6) << "bad"
              << std::setw(12) << "median ms" << std::setw(10) << "p99 ms" << std::setw(10)
              << "max ms" << std::setw(8) << "CPU %"
              << "\n";
    for (const auto& j : list)
      std::cout << std::left << std::setw(10) << j["device"].get<std::string>() << std::setw(6)
                << j["link"].get<std::string>() << std::right << std::fixed << std::setprecision(0)
                << std::setw(8) << j["rate_hz"].get<double>() << std::setw(8)
                << j["scans"].get<std::int64_t>() << std::setw(6)
                << j["bad_replies"].get<std::int64_t>() << std::setprecision(3) << std::setw(12)
                << db::ms(j["latency_ms_median"]) << std::setw(10) << db::ms(j["latency_ms_p99"])
                << std::setw(10) << db::ms(j["latency_ms_max"]) << std::setprecision(2)
                << std::setw(8) << j["cpu_percent"].get<double>() << "\n";
    result = 0;
  });
}

}  // namespace tessera::app
