// VectorNavDevice: see vectornav_device.hpp.
#include <tessera/drivers/vectornav_device.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace tessera::drivers {

namespace vectornav_device_detail {

/// A register number or value: decimal digits only; -1 otherwise.
int integer(const std::string& s) {
  int v = -1;
  if (s.empty() || !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return -1;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && end == s.data() + s.size() ? v : -1;
}

bool among(const std::vector<int>& values, int v) {
  return std::find(values.begin(), values.end(), v) != values.end();
}

}  // namespace vectornav_device_detail

VectorNavDevice::VectorNavDevice(int power_up_baud, std::uint64_t seed)
    : power_up_baud_(power_up_baud), rng_(seed), baud_(power_up_baud) {
  if (!vectornav_device_detail::among(vn::baudRates(), power_up_baud))
    throw std::invalid_argument("VectorNavDevice: " + std::to_string(power_up_baud) +
                                " is not a VN-100 baud rate");
}

void VectorNavDevice::restart(std::int64_t now_ns) {
  baud_ = power_up_baud_;
  type_ = vn::kTypeYmr;
  rate_hz_ = 40;
  outgoing_.clear();
  splitter_ = vn::LineSplitter();
  last_ns_ = 0;  // starts the clock again at the next call
  line_free_ns_ = now_ns;
}

std::int64_t VectorNavDevice::lineTime(std::size_t bytes) const {
  return static_cast<std::int64_t>(bytes) * 10 * 1'000'000'000LL / baud_;
}

bool VectorNavDevice::carries(int type, int rate_hz, int baud) const {
  if (type == vn::kTypeOff) return true;
  return static_cast<std::int64_t>(rate_hz) * static_cast<std::int64_t>(vn::lineBytes(type)) * 10 <=
         baud;
}

void VectorNavDevice::reply(const std::string& body, std::int64_t now_ns) {
  if (faults_.silent) return;
  std::string bytes = vn::frame(body);
  damage(bytes, faults_, rng_);
  // In due order: a late reply does not hold the output lines back.
  outgoing_.queue(now_ns + static_cast<std::int64_t>(std::max(0.0, faults_.reply_delay_s) * 1e9),
                  std::move(bytes));
}

void VectorNavDevice::error(int code, std::int64_t now_ns) {
  reply((code < 10 ? "VNERR,0" : "VNERR,") + std::to_string(code), now_ns);
}

void VectorNavDevice::receive(std::string_view bytes, std::int64_t now_ns) {
  if (last_ns_ == 0) (void)poll(now_ns);  // starts its clock; nothing is due yet
  for (const auto& line : splitter_.feed(bytes)) {
    if (line.cut) continue;  // never a whole command
    ++commands_;
    if (faults_.silent) continue;
    vn::Problem p;
    const auto m = vn::parseLine(line.text, p, true);
    if (!m) {
      error(p.fault == vn::Fault::kChecksum ? 3 : 4, now_ns);
      continue;
    }
    command(*m, now_ns);
  }
}

void VectorNavDevice::command(const vn::Message& m, std::int64_t now_ns) {
  namespace d = vectornav_device_detail;
  const auto& f = m.fields;
  const bool read = m.header == "VNRRG";
  if (!read && m.header != "VNWRG") return error(4, now_ns);
  const std::size_t wanted = read ? 1 : 2;
  if (f.size() < wanted) return error(5, now_ns);
  if (f.size() > wanted) return error(6, now_ns);
  const int reg = d::integer(f[0]);
  if (read) {
    std::string value;
    switch (reg) {
      case vn::kModelRegister:
        value = kModel;
        break;
      case vn::kSerialRegister:
        value = kSerialNumber;
        break;
      case vn::kBaudRegister:
        value = std::to_string(baud_);
        break;
      case vn::kTypeRegister:
        value = std::to_string(type_);
        break;
      case vn::kRateRegister:
        value = std::to_string(rate_hz_);
        break;
      default:
        return error(reg < 0 ? 7 : 8, now_ns);
    }
    std::string body = "VNRRG,";
    body.append(f[0]).append(",").append(value);
    return reply(body, now_ns);
  }
  const int v = d::integer(f[1]);
  switch (reg) {
    case vn::kModelRegister:
    case vn::kSerialRegister:
      return error(9, now_ns);  // read-only
    case vn::kBaudRegister:
      if (!d::among(vn::baudRates(), v)) return error(7, now_ns);
      outgoing_.changeBaudWhenSent(v);  // after the reply has gone out at the old rate
      break;
    case vn::kTypeRegister:
      if (!d::among({vn::kTypeOff, vn::kTypeYpr, vn::kTypeYmr, vn::kTypeImu}, v))
        return error(7, now_ns);
      if (!carries(v, rate_hz_, baud_)) return error(12, now_ns);
      type_ = v;
      break;
    case vn::kRateRegister:
      if (!d::among(vn::outputRates(), v)) return error(7, now_ns);
      if (!carries(type_, v, baud_)) return error(12, now_ns);
      rate_hz_ = v;
      next_line_ns_ = now_ns + 1'000'000'000LL / v;
      break;
    default:
      return error(reg < 0 ? 7 : 8, now_ns);
  }
  std::string body = "VNWRG,";
  body.append(f[0]).append(",").append(f[1]);
  reply(body, now_ns);
}

std::string VectorNavDevice::sampleLine(std::int64_t at_ns) {
  // Heading turns clockwise seen from above, against REP-103's counter-clockwise z.
  const double dt = static_cast<double>(at_ns - last_ns_) * 1e-9;
  last_ns_ = at_ns;
  yaw_deg_ -= motion_.angular_velocity[2] * dt * 180 / std::numbers::pi;
  yaw_deg_ = std::remainder(yaw_deg_, 360.0);
  std::array<double, 3> gyro = motion_.angular_velocity, accel = motion_.specific_force;
  if (motion_.gyro_noise > 0) {
    std::normal_distribution<double> n(0, motion_.gyro_noise);
    for (auto& x : gyro) x += n(rng_);
  }
  if (motion_.accel_noise > 0) {
    std::normal_distribution<double> n(0, motion_.accel_noise);
    for (auto& x : accel) x += n(rng_);
  }
  vn::Sample s;
  s.type = type_;
  s.yaw_deg = yaw_deg_;
  s.pitch_deg = s.roll_deg = 0;
  // The earth's field, 0.2 G north and 0.45 G down, seen at this heading.
  const double h = yaw_deg_ * std::numbers::pi / 180;
  s.mag_gauss = {0.2 * std::cos(h), -0.2 * std::sin(h), 0.45};
  s.gyro = vn::fromRep103(gyro);
  s.accel = vn::fromRep103(accel);
  s.temperature_c = 25.0;
  s.pressure_kpa = 101.325;
  return vn::frame(vn::encodeSample(s));
}

std::string VectorNavDevice::poll(std::int64_t now_ns) {
  if (last_ns_ == 0) {  // powered up now
    last_ns_ = now_ns;
    next_line_ns_ = now_ns + 1'000'000'000LL / rate_hz_;
    line_free_ns_ = std::max(line_free_ns_, now_ns);
  }
  while (next_line_ns_ <= now_ns) {
    const std::int64_t at = next_line_ns_;
    next_line_ns_ += 1'000'000'000LL / rate_hz_;
    if (type_ == vn::kTypeOff || faults_.silent) continue;
    std::string line = sampleLine(at);
    if (line_free_ns_ > at) {  // the line is still busy at this baud rate
      ++lines_skipped_;
      continue;
    }
    // Only the output lines occupy the line in this model: replies are a few bytes.
    line_free_ns_ = at + lineTime(line.size());
    damage(line, faults_, rng_);
    outgoing_.queue(at, std::move(line));
    ++lines_sent_;
  }
  return outgoing_.take(now_ns, baud_);
}

std::optional<std::int64_t> VectorNavDevice::nextDue() const {
  std::optional<std::int64_t> due = outgoing_.nextDue();
  if (type_ != vn::kTypeOff && !faults_.silent && last_ns_ != 0 && (!due || next_line_ns_ < *due))
    due = next_line_ns_;
  return due;
}

}  // namespace tessera::drivers
