#include <tessera/drivers/create_base_actor.hpp>

#include <tessera/runtime/registry.hpp>

namespace tessera::drivers {

namespace create_actor_detail {

CreateBase checkedBase(const CreateBaseActorOptions& o) {
  checkLinkOptions("create_base", {o.device, o.baud, o.retry_initial_s, o.retry_max_s});
  if (o.baud != 115200 && o.baud != 19200)
    throw ConfigError("create_base: option 'baud': the OI runs at 115200 or 19200, not " +
                      std::to_string(o.baud));
  try {
    return CreateBase(o.base);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("create_base: option 'base': ") + e.what());
  }
}

}  // namespace create_actor_detail

CreateBaseActor::CreateBaseActor(CreateBaseActorOptions options)
    : options_(std::move(options)), base_(create_actor_detail::checkedBase(options_)) {}

CreateBaseActor::~CreateBaseActor() {
  if (loop_) loop_->stop();
}

void CreateBaseActor::configure(ActorContext& ctx) {
  requireWallClock("create_base", ctx);
  ticks_pub_ = ctx.advertise<msg::WheelTicks>("wheel_ticks");
  status_pub_ = ctx.advertise<msg::BaseStatus>("base_status");
  ctx.subscribe<msg::Twist>("base_cmd", MailboxPolicy::keepLatest(1),
                            [this](const Message<msg::Twist>& m) {
                              const auto t = m->getTwist();
                              {
                                std::lock_guard lock(mutex_);
                                pending_ = Command{t.getVx(), t.getOmega()};
                              }
                              if (loop_) loop_->wake();
                            });
  DeviceHooks h;
  h.connected = [this](Nanos now) { return take(base_.connected(now)); };
  h.received = [this](std::string_view bytes, Nanos now, Nanos) {
    return take(base_.received(bytes, now));
  };
  h.tick = [this](Nanos now) {
    std::optional<Command> c;
    {
      std::lock_guard lock(mutex_);
      c = std::exchange(pending_, std::nullopt);
    }
    BaseOutput out = c ? base_.command(c->vx, c->omega, now) : BaseOutput{};
    BaseOutput timed = base_.tick(now);
    out.send += timed.send;
    for (auto& s : timed.status) out.status.push_back(std::move(s));
    for (auto& e : timed.events) out.events.push_back(std::move(e));
    out.reconnect = timed.reconnect;
    out.reconnect_reason = std::move(timed.reconnect_reason);
    return take(std::move(out));
  };
  h.disconnected = [this] { base_.disconnected(); };
  h.streaming = [this] { return base_.streaming(); };
  h.progress = [this] { return base_.counters().frames; };
  loop_ = std::make_unique<DeviceLoop>(
      "create_base",
      DeviceLinkOptions{options_.device, options_.baud, options_.retry_initial_s,
                        options_.retry_max_s},
      std::move(h), ctx);
}

DeviceStep CreateBaseActor::take(BaseOutput&& out) {
  const auto& g = options_.base;
  for (const auto& t : out.ticks) {
    auto loan = ticks_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), t.stamp_ns, options_.frame_id, ticks_pub_.nextSeq());
    b.setLeft(t.left);
    b.setRight(t.right);
    b.setTicksPerRevolution(g.counts_per_revolution);
    b.setWheelRadius(g.wheel_radius_m);
    b.setWheelBase(g.wheel_base_m);
    ticks_pub_.publish(std::move(loan));
  }
  for (const auto& s : out.status) {
    auto loan = status_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), s.stamp_ns, options_.frame_id, status_pub_.nextSeq());
    const auto& f = s.sensors;
    b.setBumpLeft(f.bump_left);
    b.setBumpRight(f.bump_right);
    b.setWheelDropLeft(f.wheel_drop_left);
    b.setWheelDropRight(f.wheel_drop_right);
    b.setCliffLeft(f.cliff_left);
    b.setCliffFrontLeft(f.cliff_front_left);
    b.setCliffFrontRight(f.cliff_front_right);
    b.setCliffRight(f.cliff_right);
    b.setBatteryVoltage(f.voltage_mv * 1e-3);
    b.setBatteryCurrent(f.current_ma * 1e-3);
    b.setBatteryCharge(f.charge_mah * 1e-3);
    b.setBatteryCapacity(f.capacity_mah * 1e-3);
    b.setCharging(f.charging_state >= 1 && f.charging_state <= 3);  // reconditioning, full, trickle
    b.setMoving(s.moving);
    b.setStopReason(s.stop_reason);
    status_pub_.publish(std::move(loan));
  }
  {
    std::lock_guard lock(mutex_);
    counters_ = base_.counters();
    if (!out.status.empty() && !out.status.back().stop_reason.empty())
      last_stop_reason_ = out.status.back().stop_reason;
  }
  DeviceStep step;
  step.send = std::move(out.send);
  step.events = std::move(out.events);
  step.reconnect = out.reconnect;
  step.reconnect_reason = std::move(out.reconnect_reason);
  return step;
}

void CreateBaseActor::start() {
  loop_->start();
}

void CreateBaseActor::stop() {
  if (loop_) loop_->stop();
}

void CreateBaseActor::summarize(Summary& out) const {
  if (loop_) loop_->summarize(out);
  std::lock_guard lock(mutex_);
  out["frames"] = counters_.frames;
  out["bad_frames"] = counters_.bad_frames;
  out["commands"] = counters_.commands;
  out["watchdog_stops"] = counters_.watchdog_stops;
  out["safety_stops"] = counters_.safety_stops;
  out["refused_commands"] = counters_.refused_commands;
  out["garbage_bytes"] = static_cast<std::int64_t>(counters_.garbage_bytes);
  out["last_stop_reason"] = last_stop_reason_;
}

TESSERA_REGISTER_ACTOR("create_base", CreateBaseActor, CreateBaseActorOptions,
                       "iRobot Create 2 base over the Open Interface: drive, encoders, bumpers, "
                       "cliffs, battery, with a watchdog");

}  // namespace tessera::drivers
