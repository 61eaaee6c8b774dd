#include <tessera/drivers/vectornav_actor.hpp>

#include <tessera/runtime/registry.hpp>

namespace tessera::drivers {

namespace vectornav_actor_detail {

VectorNavImu checkedImu(const VectorNavActorOptions& o) {
  checkLinkOptions("vectornav", {o.device, o.baud, o.retry_initial_s, o.retry_max_s});
  try {
    return VectorNavImu(o.imu, o.baud);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    throw ConfigError(std::string("vectornav: option '") +
                      (what.rfind("baud", 0) == 0 ? "baud" : "imu") + "': " + what);
  }
}

}  // namespace vectornav_actor_detail

VectorNavActor::VectorNavActor(VectorNavActorOptions options)
    : options_(std::move(options)), imu_(vectornav_actor_detail::checkedImu(options_)) {}

VectorNavActor::~VectorNavActor() {
  if (loop_) loop_->stop();
}

void VectorNavActor::configure(ActorContext& ctx) {
  requireWallClock("vectornav", ctx);
  pub_ = ctx.advertise<msg::ImuSample>("imu");
  DeviceHooks h;
  h.open_baud = [this](int) { return imu_.openBaud(); };
  h.connected = [this](Nanos now) { return take(imu_.connected(now)); };
  h.received = [this](std::string_view bytes, Nanos now, Nanos) {
    return take(imu_.received(bytes, now));
  };
  h.tick = [this](Nanos now) { return take(imu_.tick(now)); };
  h.disconnected = [this] { imu_.disconnected(); };
  h.streaming = [this] { return imu_.streaming(); };
  h.progress = [this] { return imu_.counters().samples; };
  loop_ = std::make_unique<DeviceLoop>(
      "vectornav",
      DeviceLinkOptions{options_.device, options_.baud, options_.retry_initial_s,
                        options_.retry_max_s},
      std::move(h), ctx);
}

DeviceStep VectorNavActor::take(ImuOutput&& out) {
  for (const auto& r : out.samples) {
    auto loan = pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), r.stamp_ns, options_.frame_id, pub_.nextSeq());
    b.setAngularVelocityX(r.gyro[0]);
    b.setAngularVelocityY(r.gyro[1]);
    b.setAngularVelocityZ(r.gyro[2]);
    b.setLinearAccelerationX(r.accel[0]);
    b.setLinearAccelerationY(r.accel[1]);
    b.setLinearAccelerationZ(r.accel[2]);
    pub_.publish(std::move(loan));
  }
  {
    std::lock_guard lock(mutex_);
    counters_ = imu_.counters();
    model_ = imu_.model();
  }
  DeviceStep step;
  step.switch_baud = out.switch_baud;
  step.send = std::move(out.send);
  step.events = std::move(out.events);
  step.reconnect = out.reconnect;
  step.reconnect_reason = std::move(out.reconnect_reason);
  return step;
}

void VectorNavActor::start() {
  loop_->start();
}

void VectorNavActor::stop() {
  if (loop_) loop_->stop();
}

void VectorNavActor::summarize(Summary& out) const {
  if (loop_) loop_->summarize(out);
  std::lock_guard lock(mutex_);
  const auto& c = counters_;
  out["samples"] = c.samples;
  out["sessions"] = c.sessions;
  out["bad_lines"] = c.badLines();
  out["truncated"] = c.truncated;
  out["malformed"] = c.malformed;
  out["bad_checksum"] = c.bad_checksum;
  out["not_finite"] = c.not_finite;
  out["device_errors"] = c.device_errors;
  out["garbage_bytes"] = static_cast<std::int64_t>(c.garbage_bytes);
  out["model"] = model_;
}

TESSERA_REGISTER_ACTOR("vectornav", VectorNavActor, VectorNavActorOptions,
                       "VectorNav VN-100 IMU over its ASCII serial protocol: angular rate and "
                       "acceleration on imu (REP-103)");

}  // namespace tessera::drivers
