# Keyframes of the RGB-D visual SLAM front end and the keyframe pose graph's input and output.
# Evolve by Cap'n Proto rules: add fields, never renumber. Bulk Data fields are allocated after
# every small field (see message.hpp: Loan size hint). Poses are camera-to-world (x_world = T
# x_camera), the camera in the optical convention (x right, y down, z forward); metres.
@0xf5a5029cdf8609af;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";
using Image = import "image.capnp";

# One image feature (OpenCV KeyPoint semantics).
struct KeyPoint {
  u @0 :Float32;         # [px] column
  v @1 :Float32;         # [px] row
  size @2 :Float32;      # [px] diameter of the meaningful neighbourhood
  angle @3 :Float32;     # [deg] orientation, -1 = none
  octave @4 :Int32;      # pyramid level (as the detector packs it)
  response @5 :Float32;  # detector strength
}

# A point in the camera frame [m]; valid = false where the depth gave none.
struct CameraPoint {
  x @0 :Float32;
  y @1 :Float32;
  z @2 :Float32;
  valid @3 :Bool;
}

# A keyframe as the front end made it: the features that have a 3D point, reliably published.
struct Keyframe {
  header @0 :Common.Header;            # stamp of the frame; frameId = the world frame
  id @1 :UInt32;                       # 0, 1, ... in insertion order
  frameIndex @2 :UInt32;               # index of the frame it was made from
  pose @3 :Image.Pose3D;               # camera-to-world of the tracker (not optimised)
  intrinsics @4 :Image.CameraIntrinsics;  # of the image the keypoints are in
  keypoints @5 :List(KeyPoint);
  # Descriptors: descriptorRows rows of descriptorBytes bytes, row-major, one row per keypoint.
  # descriptorType: "u8" (binary, e.g. ORB: Hamming distance) or "f32" (e.g. SIFT, little-endian).
  descriptorRows @6 :UInt32;
  descriptorBytes @7 :UInt32;
  descriptorType @8 :Text;
  points @9 :List(CameraPoint);        # one per keypoint, in the camera frame
  # Depth for clouds: every depthStep-th pixel of every depthStep-th row of the depth image
  # (depthWidth x depthHeight values, uint16 little-endian, 0 = no reading, metres = value /
  # depthScale). The full-resolution pixel of sample (i, j) is (i * depthStep, j * depthStep).
  depthStep @10 :UInt32;
  depthWidth @11 :UInt32;
  depthHeight @12 :UInt32;
  depthScale @13 :Float64;
  depth @14 :Data;
  datasetTimeS @15 :Float64;           # [s] the frame's own timestamp in its dataset
  trackingInliers @16 :UInt32;         # PnP inliers of the frame's tracking (0 = unknown)
  descriptors @17 :Data;               # descriptorRows x descriptorBytes bytes (see above)
}

# One keyframe's pose after an optimisation of the keyframe graph.
struct KeyframePose {
  id @0 :UInt32;
  pose @1 :Image.Pose3D;                # camera-to-world
}

# The poses of every keyframe the graph holds, after an optimisation (or at stop). A keyframe
# with an id below the newest listed that is missing has left the graph (lifelong mode trims
# covered keyframes; a rejected one never entered it): its consumers may drop it. So any one
# message says all there is, and a keep_latest subscriber misses nothing by skipping some.
struct KeyframePoses {
  header @0 :Common.Header;             # stamp of the newest input; frameId = world frame
  poses @1 :List(KeyframePose);         # by increasing id
  chi2 @2 :Float64;                     # of the optimised graph (g2o objective)
  iterations @3 :UInt32;
}

# A relative-pose constraint between two keyframes (a loop closure, usually): the pose of
# keyframe `to` in the frame of keyframe `from`, with its 6x6 covariance over (x y z rx ry rz)
# in relative.covariance (36 values, row-major).
struct KeyframeConstraint {
  header @0 :Common.Header;
  fromId @1 :UInt32;
  toId @2 :UInt32;
  relative @3 :Image.Pose3D;
  inliers @4 :UInt32;                   # geometric-verification inliers (0 = unknown)
}
