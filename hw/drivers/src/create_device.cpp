// CreateDevice: see create_device.hpp.
#include <tessera/drivers/create_device.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tessera::drivers {

namespace create_device_detail {

constexpr std::int64_t kFrameNs = 15'000'000;
constexpr double kCountsPerMetre = 508.8 / (std::numbers::pi * 0.072);

/// Bytes a command takes, opcode included; 0 when unknown (ignored, like the robot does);
/// -1 when its length comes from its next byte (Stream).
int commandLength(std::uint8_t op) {
  switch (op) {
    case oi::kStart:
    case oi::kSafe:
    case oi::kFull:
    case oi::kStop:
      return 1;
    case oi::kPauseResume:
      return 2;
    case oi::kDriveDirect:
      return 5;
    case oi::kStream:
      return -1;
    default:
      return 0;
  }
}

}  // namespace create_device_detail

CreateDevice::CreateDevice(std::uint64_t seed) : rng_(seed) {
  world_.voltage_mv = 14800;
  world_.charge_mah = 2500;
  world_.capacity_mah = 3000;
  world_.current_ma = -150;
}

void CreateDevice::restart(std::int64_t now_ns) {
  mode_ = Mode::kOff;
  command_.clear();
  streaming_ = false;
  right_mm_s_ = left_mm_s_ = 0;
  last_ns_ = now_ns;
}

void CreateDevice::advance(std::int64_t now_ns) {
  if (last_ns_ == 0) last_ns_ = now_ns;
  const double dt = static_cast<double>(now_ns - last_ns_) * 1e-9;
  last_ns_ = now_ns;
  if (dt <= 0) return;
  right_m_ += right_mm_s_ * 1e-3 * dt;
  left_m_ += left_mm_s_ * 1e-3 * dt;
}

void CreateDevice::receive(std::string_view bytes, std::int64_t now_ns) {
  namespace d = create_device_detail;
  advance(now_ns);
  for (const char c : bytes) {
    command_ += c;
    const auto op = static_cast<std::uint8_t>(command_[0]);
    int length = d::commandLength(op);
    if (length == 0) {  // not an opcode the robot knows: dropped
      command_.clear();
      continue;
    }
    if (length < 0)
      length = command_.size() >= 2 ? 2 + static_cast<std::uint8_t>(command_[1]) : 1000;
    if (static_cast<int>(command_.size()) < length) continue;
    if (!faults_.silent) execute(now_ns);
    command_.clear();
  }
}

void CreateDevice::execute(std::int64_t now_ns) {
  const auto op = static_cast<std::uint8_t>(command_[0]);
  const auto be16 = [this](std::size_t at) {
    return static_cast<std::int16_t>((static_cast<std::uint8_t>(command_[at]) << 8) |
                                     static_cast<std::uint8_t>(command_[at + 1]));
  };
  switch (op) {
    case oi::kStart:
      if (mode_ == Mode::kOff) mode_ = Mode::kPassive;
      return;
    case oi::kSafe:
    case oi::kFull:
      if (mode_ != Mode::kOff) mode_ = op == oi::kSafe ? Mode::kSafe : Mode::kFull;
      return;
    case oi::kStop:
      mode_ = Mode::kOff;
      streaming_ = false;
      right_mm_s_ = left_mm_s_ = 0;
      return;
    case oi::kPauseResume:
      streaming_ = command_[1] != 0 && mode_ != Mode::kOff;
      return;
    case oi::kDriveDirect:
      if (mode_ != Mode::kSafe && mode_ != Mode::kFull) return;  // Passive does not drive
      right_mm_s_ = std::clamp<int>(be16(1), -500, 500);
      left_mm_s_ = std::clamp<int>(be16(3), -500, 500);
      return;
    case oi::kStream:
      if (mode_ == Mode::kOff) return;
      streaming_ = true;
      next_frame_ns_ = now_ns + create_device_detail::kFrameNs;
      return;
    default:
      return;
  }
}

std::string CreateDevice::poll(std::int64_t now_ns) {
  namespace d = create_device_detail;
  std::string out;
  while (streaming_ && next_frame_ns_ <= now_ns) {
    advance(next_frame_ns_);
    // Safe mode: a cliff or a wheel drop stops the wheels and drops to Passive.
    if (mode_ == Mode::kSafe &&
        (world_.anyCliff() || world_.wheel_drop_left || world_.wheel_drop_right) &&
        (right_mm_s_ != 0 || left_mm_s_ != 0)) {
      right_mm_s_ = left_mm_s_ = 0;
      mode_ = Mode::kPassive;
    }
    oi::SensorFrame f = world_;
    f.left_counts = static_cast<std::uint16_t>(
        static_cast<std::int64_t>(std::floor(left_m_ * d::kCountsPerMetre)) & 0xFFFF);
    f.right_counts = static_cast<std::uint16_t>(
        static_cast<std::int64_t>(std::floor(right_m_ * d::kCountsPerMetre)) & 0xFFFF);
    std::string frame = oi::encodeFrame(f);
    if (!faults_.silent) {
      damage(frame, faults_, rng_);
      out += frame;
    }
    next_frame_ns_ += d::kFrameNs;
  }
  advance(now_ns);
  return out;
}

std::optional<std::int64_t> CreateDevice::nextDue() const {
  if (!streaming_) return std::nullopt;
  return next_frame_ns_;
}

}  // namespace tessera::drivers
