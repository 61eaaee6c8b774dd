// Readers for point-landmark datasets: UTIAS MRCLAM (5 robots, barcoded landmarks, range-bearing
// from a camera) and the GTSAM text conversion of Victoria Park (car, tree trunks from a laser).
// Plain data, no runtime types; the landmark_player actor turns these into messages.
//
// UTIAS MRCLAM (one dataset folder; times are Unix seconds, given to 1 ms):
//   Barcodes.dat              subject barcode            subject 1..5 = robots, 6..20 = landmarks
//   Landmark_Groundtruth.dat  subject x y std_x std_y    [m] Vicon, in the world frame
//   RobotN_Odometry.dat(.gz)  time v omega               [s, m/s, rad/s]; holds until the next row
//   RobotN_Measurement.dat(.gz) time barcode range bearing  [s, -, m, rad]; the column header says
//                             "Subject #" but the values are BARCODES (e.g. 90 = subject 16)
//   RobotN_Groundtruth.dat(.gz) time x y theta           optional: absent from the shared copy
//   Measurements of a barcode that belongs to a robot (subjects 1..5) are KEPT with is_robot =
//   true and landmark_index = -1, so cooperative-localisation users can have them while
//   landmark SLAM users filter them out. A barcode missing from Barcodes.dat (barcode 43 appears
//   3 times in dataset 1) is a counted skip "unknown barcode". The landmark index is the row of
//   the subject in Landmark_Groundtruth.dat (0-based; subjects 6..20 -> 0..14 in dataset 1).
//   Times must not decrease within a file (equal times are kept: several sightings per frame,
//   and repeated odometry stamps).
//
// Victoria Park, GTSAM text (victoria_park.txt):
//   ODOMETRY i j dx dy dtheta c11 c12 c13 c22 c23 c33   pose j in the frame of pose i; the six
//       numbers are a COVARIANCE in g2o (row-major upper-triangle) order; GTSAM's load2D picks
//       that reading ("NoiseFormatCOV") for this file's pattern 0.0001 0 0 4e-06 0 4e-06.
//   LANDMARK i l lx ly vxx vxy vyy   landmark l seen from pose i at (lx, ly) in the ROBOT frame,
//       with its 2x2 covariance. range = hypot(lx, ly), bearing = atan2(ly, lx). Following GTSAM,
//       when vxx == vyy (|diff| < 1e-4, as everywhere in the file) the xy covariance is taken as
//       the uncertainty at 10 m: range_std = sqrt(vxx), bearing_std = sqrt(vxx / 10); otherwise
//       the larger eigenvalue e is used the same way (sqrt(e), sqrt(e / 10)).
//   Pose and landmark ids share one id space: the odometry chain skips ids used by landmarks
//   (ODOMETRY 4 6, because 5 is a landmark). Pose ids (every id in ODOMETRY and first in LANDMARK)
//   map to a dense pose index in increasing id order, landmark ids to a dense landmark index in
//   increasing id order; original ids are kept. The k-th ODOMETRY line must go from pose index k
//   to k + 1 (a chain; anything else is an error), an id used as both pose and landmark is an
//   error, and a sighting at zero range (no bearing) is a counted skip.
#pragma once

#include <tessera/io/text_reader.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <vector>

namespace tessera::datasets {

// ---- UTIAS MRCLAM ----

constexpr int kMrclamRobots = 5;  // subjects 1..5 are the robots

struct MrclamLandmark {
  int subject = 0;
  int barcode = 0;
  double x = 0, y = 0;          // [m]
  double std_x = 0, std_y = 0;  // [m] Vicon 1-sigma
};

struct MrclamOdometry {
  double time = 0;   // [s]
  double v = 0;      // [m/s] forward speed
  double omega = 0;  // [rad/s]
};

struct MrclamMeasurement {
  double time = 0;  // [s]
  int barcode = 0;
  int subject = 0;
  double range = 0;    // [m]
  double bearing = 0;  // [rad] as in the file
  bool is_robot = false;
  int landmark_index = -1;  // row in Landmark_Groundtruth.dat; -1 for robots
};

struct MrclamPose {
  double time = 0, x = 0, y = 0, theta = 0;
};

struct MrclamRobotLog {
  int robot = 1;
  std::map<int, int> barcode_to_subject;
  std::vector<MrclamLandmark> landmarks;  // index = landmark index
  std::vector<MrclamOdometry> odometry;
  std::vector<MrclamMeasurement> measurements;
  std::vector<MrclamPose> ground_truth;  // empty when RobotN_Groundtruth.dat is absent
  io::ParseReport report;                // summed over the files read
};

// Reads Barcodes.dat, Landmark_Groundtruth.dat and robot `robot`'s files from `folder`; each
// RobotN_*.dat may also be RobotN_*.dat.gz. Throws io::DatasetError.
MrclamRobotLog readMrclam(const std::filesystem::path& folder, int robot);

// The single files, for tests and tools.
std::map<int, int> readMrclamBarcodes(io::TextReader& reader);  // barcode -> subject
std::vector<MrclamLandmark> readMrclamLandmarks(io::TextReader& reader,
                                                const std::map<int, int>& barcode_to_subject);
std::vector<MrclamOdometry> readMrclamOdometry(io::TextReader& reader, io::ParseReport& report);
std::vector<MrclamMeasurement> readMrclamMeasurements(io::TextReader& reader,
                                                      const std::map<int, int>& barcode_to_subject,
                                                      const std::vector<MrclamLandmark>& landmarks,
                                                      io::ParseReport& report);
std::vector<MrclamPose> readMrclamGroundTruth(io::TextReader& reader, io::ParseReport& report);

// ---- Victoria Park (GTSAM text) ----

struct VictoriaOdometry {
  std::int64_t from_id = 0, to_id = 0;
  std::size_t from_index = 0;                       // dense pose index; to_index = from_index + 1
  Eigen::Vector3d delta = Eigen::Vector3d::Zero();  // (dx, dy, dtheta) of `to` in `from`
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};

struct VictoriaObservation {
  std::int64_t pose_id = 0, landmark_id = 0;
  std::size_t pose_index = 0, landmark_index = 0;
  Eigen::Vector2d position = Eigen::Vector2d::Zero();  // [m] in the robot frame
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
  double range = 0, bearing = 0;          // [m], [rad] in (-pi, pi]
  double range_std = 0, bearing_std = 0;  // GTSAM's reading, see above
};

struct VictoriaParkLog {
  std::vector<VictoriaOdometry> odometry;         // odometry[k] goes from pose k to pose k + 1
  std::vector<VictoriaObservation> observations;  // in file order (by pose)
  std::vector<std::int64_t> pose_ids;             // dense pose index -> original id
  std::vector<std::int64_t> landmark_ids;         // dense landmark index -> original id
  io::ParseReport report;
};

VictoriaParkLog readVictoriaPark(const std::filesystem::path& path);
VictoriaParkLog readVictoriaPark(io::TextReader& reader);

}  // namespace tessera::datasets
