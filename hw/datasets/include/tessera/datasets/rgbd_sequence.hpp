// RGB-D sequences on disk: an index of frames (timestamps, image paths, ground-truth poses,
// camera intrinsics, depth scale) read from the text files of a dataset folder, and a loader that
// decodes one frame's images into plain buffers. Two layouts:
//
//  * TUM RGB-D (Sturm et al., IROS 2012): rgb.txt / depth.txt ("timestamp file" lines),
//    optional groundtruth.txt ("t tx ty tz qx qy qz qw", motion capture, pose of the colour
//    camera's optical centre in the mocap world frame) and optional associations.txt
//    ("t_rgb rgb_file t_depth depth_file"). Colour and depth are paired like TUM's associate.py:
//    every (rgb, depth) pair closer than max_time_difference is a candidate, candidates are taken
//    closest first, each image used at most once. Other files in the folder (e.g. the
//    *_full_sequence.txt lists kept for reference in our 9-frame copy) are ignored. Depth is
//    16-bit PNG at 5000 units per metre; the Kinect driver registered it to the colour camera.
//    Intrinsics: TUM's published calibration of the freiburg1/2/3 Kinects (see
//    tumIntrinsics()), chosen by TumOptions::camera or recognised from the folder name or the
//    "# file: 'rgbd_dataset_freiburgN_...'" header of rgb.txt.
//  * Microsoft 7-Scenes (Shotton et al., CVPR 2013): frame-NNNNNN.color.{png,jpg},
//    frame-NNNNNN.depth.png (millimetres, 65535 = invalid), frame-NNNNNN.pose.txt (4x4
//    camera-to-world, row-major) and, when present, camera-intrinsics.txt (3x3 K; otherwise the
//    dataset's stated 585/585/320/240). 7-Scenes has no timestamps: frame k is at k / fps
//    (30 Hz, the Kinect's nominal rate). Colour is NOT registered to depth and the colour
//    camera's calibration is not published: intrinsics and poses refer to the depth camera, and
//    RgbdSequence::color_registered is false. We do not attempt a registration; colour pixel
//    (u, v) only approximately sees what depth pixel (u, v) sees. Other files (3DMatch's
//    gravity-direction.txt, a derived groundtruth_tum.txt) are ignored.
//
// Units and frames: timestamps in seconds, positions in metres, poses are camera-to-world
// (x_world = pose * x_camera) with the camera in the optical convention (x right, y down,
// z forward). Depth after loading: uint16 with 0 = no reading (7-Scenes' 65535 is rewritten to 0),
// metres = value / depth_scale.
//
// Errors: malformed text (wrong field count, NaN/inf, non-increasing time, bad rotation), a
// missing image or a corrupt/truncated image throw io::DatasetError naming the file (and line).
// Plain structs only: no OpenCV in this header.
#pragma once

#include <tessera/io/text_reader.hpp>

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::datasets {

enum class RgbdLayout { kTum, kSevenScenes };

/// "tum" / "7scenes".
std::string_view layoutName(RgbdLayout layout);
/// Parses "tum" / "7scenes" (also "sevenscenes"); throws std::invalid_argument otherwise.
RgbdLayout parseLayout(std::string_view name);
/// TUM when rgb.txt and depth.txt exist, 7-Scenes when frame-*.depth.png files do; throws
/// io::DatasetError naming the folder and what was looked for otherwise.
RgbdLayout detectRgbdLayout(const std::filesystem::path& folder);

/// Pinhole intrinsics of the image the depth is given in [px].
struct CameraIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  /// Plumb-bob (OpenCV) k1 k2 p1 p2 k3; empty = none given. The images are NOT undistorted.
  std::vector<double> distortion;
};

/// TUM's published calibration for "freiburg1", "freiburg2", "freiburg3" (or "fr1".."fr3") and
/// "ros_default" (525/525/319.5/239.5, what TUM suggests when undistortion is not wanted), all
/// 640x480. Source: the TUM RGB-D "file formats" page, section "Intrinsic Camera Calibration of
/// the Kinect" (values rounded to 0.1 px as printed there; fr1 matches our PROVENANCE.md).
/// Throws std::invalid_argument for other names.
CameraIntrinsics tumIntrinsics(std::string_view camera);

struct RgbdFrameInfo {
  std::size_t index = 0;       ///< TUM: position in the association; 7-Scenes: frame number
  double timestamp = 0;        ///< [s] of the colour image (7-Scenes: index / fps)
  double depth_timestamp = 0;  ///< [s] of the depth image (7-Scenes: = timestamp)
  std::filesystem::path color_path, depth_path;  ///< folder / name as listed
  /// Camera-to-world at `timestamp`; empty when the dataset has none for this frame.
  std::optional<Eigen::Isometry3d> pose;
};

struct RgbdSequence {
  RgbdLayout layout = RgbdLayout::kTum;
  std::filesystem::path folder;
  std::vector<RgbdFrameInfo> frames;  ///< strictly increasing timestamps
  CameraIntrinsics intrinsics;
  std::string intrinsics_source;  ///< e.g. "TUM freiburg1 (published calibration)"
  double depth_scale = 1000;      ///< depth units per metre: TUM 5000, 7-Scenes 1000
  bool color_registered = true;   ///< false: colour pixel (u,v) != depth pixel (u,v) (7-Scenes)
  bool has_ground_truth = false;  ///< the dataset provides poses (some frames may still lack one)
  std::size_t frames_without_pose = 0;  ///< frames outside the ground truth's time coverage
  std::size_t unmatched_color = 0;      ///< TUM: colour images with no depth within tolerance
  io::ParseReport report;               ///< lines read and anything skipped
};

struct TumOptions {
  /// [s] largest |t_rgb - t_depth| for a pair (TUM associate.py default).
  double max_time_difference = 0.02;
  /// Read associations.txt instead of pairing rgb.txt with depth.txt.
  bool use_associations_file = false;
  /// [s] ground truth is interpolated (position linear, rotation slerp) between the samples
  /// around the colour time when they are at most this far apart ...
  double max_interpolation_gap = 0.1;
  /// [s] ... otherwise the nearest sample is used when it is at most this far away; else none.
  double max_pose_time_difference = 0.02;
  /// "auto" (from the folder name or rgb.txt's header), or a tumIntrinsics() name.
  std::string camera = "auto";
  /// Listed images that do not exist: false = io::DatasetError, true = skipped (counted in report).
  bool skip_missing_images = false;
};

struct SevenScenesOptions {
  double fps = 30;  ///< frame k has timestamp k / fps [s]; 7-Scenes has no timestamps
};

struct RgbdReadOptions {
  std::optional<RgbdLayout> layout;  ///< empty = detectRgbdLayout()
  TumOptions tum;
  SevenScenesOptions seven_scenes;
};

/// Reads the index of a dataset folder (text files only; images are checked to exist, not
/// decoded). Throws io::DatasetError.
RgbdSequence readRgbdSequence(const std::filesystem::path& folder,
                              const RgbdReadOptions& options = {});
RgbdSequence readTumSequence(const std::filesystem::path& folder, const TumOptions& options = {});
RgbdSequence readSevenScenesSequence(const std::filesystem::path& folder,
                                     const SevenScenesOptions& options = {});

// ---- single-file parsers (building blocks, exposed for tests and tools) ----

struct TimedFile {
  double timestamp = 0;  ///< [s]
  std::string file;      ///< relative to the folder, as listed
  std::size_t line = 0;  ///< line in the list file, for errors
};
/// rgb.txt / depth.txt: "timestamp file" lines, '#' comments; timestamps strictly increasing.
std::vector<TimedFile> parseTumFileList(io::TextReader& reader);

struct TumAssociation {
  TimedFile color, depth;
};
/// associations.txt: "t_rgb rgb_file t_depth depth_file"; colour timestamps strictly increasing.
std::vector<TumAssociation> parseTumAssociations(io::TextReader& reader);

struct TimedPose {
  double timestamp = 0;  ///< [s]
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< normalised
};
/// groundtruth.txt: "t tx ty tz qx qy qz qw"; timestamps strictly increasing, quaternion norm
/// within 1e-2 of 1 (then normalised).
std::vector<TimedPose> parseTumGroundTruth(io::TextReader& reader);

/// Pairs colour with depth as TUM's associate.py does (closest first, each used once); the
/// result is sorted by colour time. Sets *unmatched_color to colour images left without depth.
std::vector<TumAssociation> associateTum(const std::vector<TimedFile>& color,
                                         const std::vector<TimedFile>& depth,
                                         double max_time_difference,
                                         std::size_t* unmatched_color = nullptr);

/// Pose at time t from `poses` (sorted): interpolated, or nearest, as TumOptions describes.
std::optional<Eigen::Isometry3d> poseAt(const std::vector<TimedPose>& poses, double t,
                                        double max_interpolation_gap,
                                        double max_pose_time_difference);

/// 7-Scenes frame-NNNNNN.pose.txt: 4 rows of 4 numbers, last row 0 0 0 1, rotation orthonormal
/// within 1e-2 (the files print ~7 digits) and det > 0; returned re-orthonormalised.
Eigen::Isometry3d parseSevenScenesPose(io::TextReader& reader);
/// camera-intrinsics.txt: 3x3 K with zero skew and last row 0 0 1. Width/height are set to
/// 640x480 (7-Scenes' Kinect), which loadRgbdImages() checks against the images.
CameraIntrinsics parseSevenScenesIntrinsics(io::TextReader& reader);

// ---- images ----

/// One frame's pixels, tightly packed, row-major, top row first.
struct RgbdImages {
  int width = 0, height = 0;
  std::vector<std::uint8_t> color;   ///< width * height * 3, channel order R, G, B
  std::vector<std::uint16_t> depth;  ///< width * height; 0 = no reading
  double depth_scale = 1000;         ///< units per metre
};

/// Decodes frame `i` of `sequence`. Checks that the colour image is 8-bit, the depth image
/// single-channel 16-bit, that both match the intrinsics' size, and that PNG/JPEG files are
/// complete (a truncated JPEG would otherwise decode as a grey-filled image). Throws
/// io::DatasetError naming the image file. Thread-safe (no shared state).
RgbdImages loadRgbdImages(const RgbdSequence& sequence, std::size_t i);

/// Depth in metres (NaN where there is no reading), same layout as images.depth.
std::vector<float> depthInMetres(const RgbdImages& images);

}  // namespace tessera::datasets
