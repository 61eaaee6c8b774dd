# Camera images and RGB-D frames (for visual odometry / SLAM). Evolve by Cap'n Proto rules: add
# fields, never renumber. Pixel arrays are Data fields; publishers allocate them after every small
# field so the bulk lands at the end of the message in one piece (see message.hpp: Loan size hint).
@0xfd8a3423414f4c36;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# One image, ROS sensor_msgs/Image semantics. Pixels are row-major, top row first; multi-byte
# pixels are little-endian (the host order on every platform Tessera supports).
struct Image {
  header @0 :Common.Header;  # frameId = the camera's optical frame
  width @1 :UInt32;          # [px]
  height @2 :UInt32;         # [px]
  # ROS image_encodings names: "rgb8", "bgr8", "mono8", "mono16", "16UC1" (depth in units of
  # RgbdFrame.depthScale per metre, 0 = no reading), "32FC1" (depth in metres, NaN = no reading).
  encoding @3 :Text;
  step @4 :UInt32;           # bytes per row (>= width * bytes per pixel)
  data @5 :Data;             # height * step bytes
}

# Pinhole camera intrinsics [px] of an image of width x height.
struct CameraIntrinsics {
  fx @0 :Float64;
  fy @1 :Float64;
  cx @2 :Float64;
  cy @3 :Float64;
  width @4 :UInt32;
  height @5 :UInt32;
  distortion @6 :List(Float64);  # plumb_bob k1 k2 p1 p2 k3; empty = none given
}

# A rigid 3D pose: position [m] and unit quaternion (Hamilton, w last as in TUM files).
struct Pose3D {
  x @0 :Float64;
  y @1 :Float64;
  z @2 :Float64;
  qx @3 :Float64;
  qy @4 :Float64;
  qz @5 :Float64;
  qw @6 :Float64 = 1;
  covariance @7 :List(Float64);  # 36 values, row-major over (x y z rx ry rz); empty = unknown
}

# Ground truth in 3D (motion capture, a dataset's reference trajectory): pose of childFrameId in
# header.frameId (the world frame).
struct GroundTruthPose3D {
  header @0 :Common.Header;
  pose @1 :Pose3D;
  childFrameId @2 :Text;
}

# An estimated 3D pose of one frame (visual odometry's per-frame camera pose): pose of
# childFrameId in header.frameId (the world frame), camera-to-world.
struct PoseStamped3D {
  header @0 :Common.Header;      # stamp of the frame the pose is for
  pose @1 :Pose3D;
  childFrameId @2 :Text;
  frameIndex @3 :UInt32;         # the frame's index in its source (RgbdFrame.frameIndex)
  status @4 :TrackingStatus;

  # How the pose was found (lost and skipped frames publish no pose).
  enum TrackingStatus {
    tracking @0;          # against the local map
    initialised @1;       # the first frame: the map starts here
    trackingPrevious @2;  # against the previous frame (the local map was too weak)
    relocalised @3;       # found again against a stored keyframe after being lost
  }
}

# One colour + depth frame of an RGB-D camera or dataset.
struct RgbdFrame {
  header @0 :Common.Header;          # stamp of the colour image; frameId = camera optical frame
  color @1 :Image;                   # "rgb8" (or "bgr8")
  depth @2 :Image;                   # "16UC1" (raw) or "32FC1" (metres)
  intrinsics @3 :CameraIntrinsics;   # of the depth image; of the colour image too if registered
  depthScale @4 :Float64;            # 16UC1 units per metre (TUM 5000, 7-Scenes 1000); 1 for 32FC1
  colorRegistered @5 :Bool;          # false: colour pixel (u,v) only roughly matches depth (u,v)
  hasGroundTruth @6 :Bool;
  groundTruth @7 :Pose3D;            # camera-to-world at the stamp, when hasGroundTruth
  datasetTimeS @8 :Float64;          # [s] the frame's own timestamp in its dataset
  depthTimeOffsetS @9 :Float64;      # [s] depth time minus colour time
  frameIndex @10 :UInt32;            # index in the dataset (7-Scenes frame number)
}
