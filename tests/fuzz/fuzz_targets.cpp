#include "fuzz_targets.hpp"

#include <tessera/datasets/carmen_log.hpp>
#include <tessera/datasets/landmark_logs.hpp>
#include <tessera/datasets/relations.hpp>
#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/datasets/urg_log.hpp>
#include <tessera/drivers/create_base.hpp>
#include <tessera/drivers/scip_client.hpp>
#include <tessera/drivers/scip_device.hpp>
#include <tessera/drivers/sick_lms_client.hpp>
#include <tessera/drivers/vectornav_imu.hpp>
#include <tessera/io/text_reader.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/recording.hpp>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>

namespace tessera::fuzz {
namespace {

using io::ParseReport;
using io::TextReader;

TextReader reader(const char* name, const std::string& text) {
  return TextReader::fromString(name, text);
}

void carmen(const std::string& text) {
  (void)datasets::parseCarmenLog("fuzz.clf", text);
}

void urg(const std::string& text) {
  (void)datasets::parseUrgLog("exp2.dat", text);
}

// A SCIP byte stream into a driver's session, in pieces: whatever arrives, the client must not
// throw, and every scan it returns must have its declared number of beams.
void scip(const std::string& text) {
  drivers::ScipClient client({});
  (void)client.connected(0);
  std::int64_t t = 0;
  for (std::size_t at = 0; at < text.size(); at += 97) {
    t += 1'000'000;
    auto out = client.received(std::string_view(text).substr(at, 97), t);
    for (const auto& s : out.scans)
      if (s.ranges.empty() || !(s.angle_increment > 0))
        throw std::logic_error("scip: a scan without beams or with a bad increment came out");
    if (out.reconnect) (void)client.connected(t);
  }
  (void)client.tick(t + 5'000'000'000);
}

// A device's answers to a driver's session: acknowledgements, PP, the MD acknowledgement and
// two scans of a URG-04LX.
std::string scipSeed() {
  namespace scip = drivers::scip;
  std::string s = scip::encodeStatusReply("SCIP2.0", "00") + scip::encodeStatusReply("QT", "00") +
                  scip::encodeParametersReply(drivers::ScipDevice::urg04lx()) +
                  scip::encodeStatusReply("MD0044072500000", "00");
  std::vector<std::uint32_t> ranges(682);
  for (std::size_t k = 0; k < ranges.size(); ++k) ranges[k] = 20 + (k * 31) % 4000;
  s += scip::encodeScanReply("MD0044072500000", "99", 1000, ranges, 3);
  s += scip::encodeScanReply("MD0044072500000", "99", 1100, ranges, 3);
  return s;
}

// An LMS byte stream into a driver's session: never an exception, never a scan of the wrong
// size.
void sickLms(const std::string& text) {
  drivers::SickLmsClient client({}, 38400);
  (void)client.openBaud(0);
  (void)client.connected(0);
  std::int64_t t = 0;
  for (std::size_t at = 0; at < text.size(); at += 61) {
    t += 1'000'000;
    auto out = client.received(std::string_view(text).substr(at, 61), t);
    for (const auto& s : out.scans)
      if (s.ranges.size() != 181) throw std::logic_error("sick: a scan of the wrong size came out");
    if (out.reconnect) {
      (void)client.openBaud(0);
      (void)client.connected(t);
    }
  }
  (void)client.tick(t + 5'000'000'000);
}

// An LMS's answers to a session at its session rate: ACKs, the stop, variant, configuration (in
// mm) and start replies, and two scans.
std::string sickSeed() {
  namespace sick = drivers::sick;
  const std::string ack(1, static_cast<char>(sick::kAck));
  std::string config(33, '\0');
  config[sick::kUnitsByte] = 1;
  std::string s = ack + sick::frame(0x80, std::string("\xA0\x00\x10", 3)) + ack +
                  sick::frame(0x80, std::string("\xBB\x01\xB4\x00\x64\x00\x10", 7)) + ack +
                  sick::frame(0x80, "\xF4" + config + "\x10") + ack +
                  sick::frame(0x80, std::string("\xA0\x00\x10", 3));
  sick::Scan scan;
  scan.millimetres = true;
  for (int k = 0; k < 181; ++k) scan.values.push_back(static_cast<std::uint16_t>(500 + k * 7));
  s += sick::frame(0x80, sick::encodeScan(scan)) + sick::frame(0x80, sick::encodeScan(scan));
  return s;
}

// A Create's sensor stream into the base session, with drive commands between the pieces:
// never an exception, never a wheel command beyond the OI's limits.
void createOi(const std::string& text) {
  drivers::CreateBase base({});
  (void)base.connected(0);
  std::int64_t t = 0;
  for (std::size_t at = 0; at < text.size(); at += 23) {
    t += 5'000'000;
    (void)base.received(std::string_view(text).substr(at, 23), t);
    const auto out = base.command(0.3, static_cast<double>(at % 7) - 3.0, t);
    if (out.send.size() % 5 != 0) throw std::logic_error("create: a drive command was cut");
    (void)base.tick(t);
  }
}

std::string createSeed() {
  drivers::oi::SensorFrame f;
  f.voltage_mv = 14800;
  f.left_counts = 65000;
  f.right_counts = 12;
  std::string s = drivers::oi::encodeFrame(f);
  f.bump_left = true;
  s += drivers::oi::encodeFrame(f);
  return s;
}

// A VN-100's byte stream into the IMU session: never an exception, never a sample that is not
// finite (NaN lines are dropped, not published).
void vectorNav(const std::string& text) {
  drivers::VectorNavImu imu({}, 115200);
  (void)imu.connected(0);
  std::int64_t t = 0;
  for (std::size_t at = 0; at < text.size(); at += 37) {
    t += 1'000'000;
    auto out = imu.received(std::string_view(text).substr(at, 37), t);
    for (const auto& s : out.samples)
      for (int k = 0; k < 3; ++k)
        if (!std::isfinite(s.gyro[k]) || !std::isfinite(s.accel[k]))
          throw std::logic_error("vectornav: a sample with a value that is not finite came out");
    if (out.reconnect) (void)imu.connected(t);
    (void)imu.tick(t);
  }
  (void)imu.tick(t + 5'000'000'000);
}

// A VN-100's answers to a session at 115200 baud: model, serial number, output type and rate,
// then VNIMU and VNYMR lines.
std::string vectorNavSeed() {
  namespace vn = drivers::vn;
  std::string s = vn::frame("VNRRG,01,VN-100T-CR") + vn::frame("VNRRG,03,0100012345") +
                  vn::frame("VNWRG,06,19") + vn::frame("VNWRG,07,100");
  vn::Sample imu;
  imu.mag_gauss = {0.2, 0, 0.45};
  imu.accel = {0.1, -0.2, -9.81};
  imu.gyro = {0.001, -0.002, -0.5};
  imu.temperature_c = 25;
  imu.pressure_kpa = 101.325;
  s += vn::frame(vn::encodeSample(imu)) + vn::frame(vn::encodeSample(imu));
  vn::Sample ymr = imu;
  ymr.type = vn::kTypeYmr;
  ymr.yaw_deg = 12.5;
  ymr.pitch_deg = ymr.roll_deg = 0.5;
  s += vn::frame(vn::encodeSample(ymr)) + vn::frame("VNERR,11");
  return s;
}

void poseGraph(const std::string& text) {
  auto r = reader("fuzz.g2o", text);
  (void)pose_graph::readPoseGraph(r);
}

void relations(const std::string& text) {
  auto r = reader("fuzz.relations", text);
  (void)datasets::readRelations(r);
}

void victoria(const std::string& text) {
  auto r = reader("victoria_park.txt", text);
  (void)datasets::readVictoriaPark(r);
}

void mrclam(const std::string& text) {
  // Measurements need the barcode and landmark tables; use a small fixed pair of them.
  auto codes_reader = reader("Barcodes.dat", "1 5\n2 14\n6 63\n7 18\n");
  const auto codes = datasets::readMrclamBarcodes(codes_reader);
  auto lm_reader = reader("Landmark_Groundtruth.dat", "6 1.0 2.0 0.001 0.001\n7 3.0 -1.0 0 0\n");
  const auto landmarks = datasets::readMrclamLandmarks(lm_reader, codes);
  ParseReport report;
  auto m = reader("Robot1_Measurement.dat", text);
  (void)datasets::readMrclamMeasurements(m, codes, landmarks, report);
  auto o = reader("Robot1_Odometry.dat", text);
  (void)datasets::readMrclamOdometry(o, report);
}

void tumLists(const std::string& text) {
  auto a = reader("rgb.txt", text);
  (void)datasets::parseTumFileList(a);
  auto b = reader("groundtruth.txt", text);
  (void)datasets::parseTumGroundTruth(b);
  auto c = reader("associations.txt", text);
  (void)datasets::parseTumAssociations(c);
}

void sevenScenes(const std::string& text) {
  auto a = reader("frame-000000.pose.txt", text);
  (void)datasets::parseSevenScenesPose(a);
  auto b = reader("camera-intrinsics.txt", text);
  (void)datasets::parseSevenScenesIntrinsics(b);
}

// Two scans: timestamp, telemetry, encoder counts, more telemetry, 682 ranges in mm.
std::string urgSeed() {
  std::string text;
  for (int scan = 0; scan < 2; ++scan) {
    text.append(std::to_string(1000000 + scan * 100000));
    text.append(" 0 ").append(std::to_string(scan * 40));
    text.append(" ").append(std::to_string(scan * 42));
    for (int i = 4; i < 24; ++i) text.append(" 0");
    for (int i = 0; i < 682; ++i)
      text.append(" ").append(std::to_string(i < 40 || i > 640 ? 0 : 1500 + i));
    text.append("\n");
  }
  return text;
}

// Recordings (runtime/recording.hpp): reading every message of a damaged file may only record
// losses; only a damaged file header is an error.
void recording(const std::string& bytes) {
  try {
    auto reader = RecordingReader::fromBytes(
        "fuzz.trec", std::vector<unsigned char>(bytes.begin(), bytes.end()));
    RecordedMessage m;
    while (reader.next(m)) (void)m.message->root().targetSize();
  } catch (const RecordingError& e) {
    throw io::DatasetError("fuzz.trec", 0, e.what());
  }
}

// A small zstd recording of two topics over three blocks.
std::string recordingSeed() {
  // One name per process: ctest runs several fuzz processes at once, and each builds this seed.
  const auto path = std::filesystem::temp_directory_path() /
                    ("tessera_fuzz_seed_" + std::to_string(::getpid()) + ".trec");
  {
    RecordingWriterOptions options;
    options.block_bytes = 512;
    options.compression = RecordingWriterOptions::Compression::kZstd;
    RecordingWriter w(path.string(),
                      {{"scan", messageTypeOf<msg::LaserScan>().id, "LaserScan"},
                       {"blob", messageTypeOf<msg::Blob>().id, "Blob"}},
                      options);
    for (int i = 0; i < 12; ++i) {
      if (i % 2 == 0) {
        auto m = makeMessage<msg::LaserScan>([&](auto b) {
          setHeader(b.initHeader(), i, "laser", static_cast<std::uint64_t>(i));
          auto r = b.initRanges(40);
          for (unsigned k = 0; k < 40; ++k) r.set(k, static_cast<float>(k + i));
        });
        w.append(0, i * 1000, *m.storage());
      } else {
        auto m =
            makeMessage<msg::Blob>([&](auto b) { b.initPayload(static_cast<unsigned>(8 * i)); });
        w.append(1, i * 1000, *m.storage());
      }
    }
    w.close();
  }
  std::ifstream in(path, std::ios::binary);
  std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  std::filesystem::remove(path);
  return text;
}

}  // namespace

const std::vector<Target>& targets() {
  static const std::vector<Target> all = {
      {"carmen",
       "CARMEN laser logs (FLASER, ODOM, ROBOTLASER1, ...)",
       carmen,
       "PARAM robot_frontlaser_offset 0.0 nohost 0\n"
       "ODOM 0 0 0 0 0 0 0.000246 pippo 0.000246\n"
       "FLASER 4 1.0 2.5 81.83 0.7 0.1 0.2 0.3 0.1 0.2 0.3 1.5 pippo 1.5\n"
       "ROBOTLASER1 0 -1.5708 3.1416 1.5708 81.9 0.01 0 3 1 2 3 0 0.1 0 0 0.1 0 0 0 0 0.5 0.5 "
       "0 2.0 host 2.0\n",
       {"intel-lab-mrpt/intel.clf.gz", "intel-lab-carmen-gfs/intel-corrected.log.gz"},
       40},
      {"urg",
       "MinesParisTech URG-04LX logs (encoders + ranges in mm)",
       urg,
       urgSeed(),
       {"mines-paristech-urg04lx-odometry/exp2.dat.gz"},
       10},
      {"scip",
       "SCIP 2.0 byte streams from a Hokuyo laser into the driver's session",
       scip,
       scipSeed(),
       {}},
      {"sick", "SICK LMS2xx telegram streams into the driver's session", sickLms, sickSeed(), {}},
      {"create",
       "iRobot Open Interface sensor streams into the base driver's session",
       createOi,
       createSeed(),
       {}},
      {"vectornav",
       "VectorNav VN-100 ASCII lines (replies, VNIMU, VNYMR) into the IMU driver's session",
       vectorNav,
       vectorNavSeed(),
       {}},
      {"posegraph",
       "g2o and TORO pose graphs, 2D and 3D",
       poseGraph,
       "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0.1\n"
       "EDGE_SE2 0 1 1 0 0.1 500 0 0 500 0 5000\n",
       {"posegraph-g2o/intel.g2o", "posegraph-toro/INTEL_P_toro.graph",
        "posegraph-g2o/manhattan.g2o", "posegraph-g2o/sphere2500.g2o"}},
      {"relations",
       "Kuemmerle et al. relations files",
       relations,
       "976052857.34 976052858.34 0.5 0.01 0 0 0 0.02\n",
       {"intel-lab-mrpt/intel.relations"}},
      {"victoria",
       "Victoria Park (GTSAM text)",
       victoria,
       "ODOMETRY 0 1 0.1 0 0.01 0.0001 0 0 4e-06 0 4e-06\n"
       "LANDMARK 1 2 11.5 -3.2 0.4 0 0.4\n"
       "ODOMETRY 1 3 0.1 0 0.01 0.0001 0 0 4e-06 0 4e-06\n",
       {"victoria-park-gtsam/victoria_park.txt"}},
      {"mrclam",
       "UTIAS MRCLAM measurement and odometry files",
       mrclam,
       "# Time [s]  Subject #  range [m]  bearing [rad]\n"
       "1248272272.841 63 3.1 0.5\n1248272273.1 14 2.0 -0.2\n",
       {"utias-mrclam-dataset1/Robot1_Measurement.dat.gz",
        "utias-mrclam-dataset1/Robot1_Odometry.dat.gz"}},
      {"tum",
       "TUM RGB-D rgb/depth/groundtruth/associations lists",
       tumLists,
       "# timestamp filename\n1305031102.175304 rgb/1305031102.175304.png\n",
       {"tum-rgbd-fr1-desk-9frames/rgb.txt", "tum-rgbd-fr1-desk-9frames/groundtruth.txt",
        "tum-rgbd-fr1-desk-9frames/associations.txt"}},
      {"recording",
       "Tessera recordings (tessera record): damaged files give losses, never a crash",
       recording,
       recordingSeed(),
       {}},
      {"7scenes",
       "7-Scenes pose and intrinsics files",
       sevenScenes,
       "1 0 0 0.1\n0 1 0 0.2\n0 0 1 0.3\n0 0 0 1\n",
       {"7scenes-redkitchen-rgbd/frame-000000.pose.txt",
        "7scenes-redkitchen-rgbd/camera-intrinsics.txt"}},
  };
  return all;
}

const Target* findTarget(std::string_view name) {
  for (const auto& t : targets())
    if (name == t.name) return &t;
  return nullptr;
}

bool runOne(const Target& target, const std::string& text) {
  try {
    target.parse(text);
  } catch (const io::DatasetError&) {
  } catch (const std::exception& e) {
    std::cerr << "fuzz " << target.name << ": a " << typeid(e).name()
              << " escaped the parser: " << e.what() << "\n";
    return false;
  }
  return true;
}

}  // namespace tessera::fuzz
