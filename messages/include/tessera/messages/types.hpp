// All Tessera message schemas plus the header helper every family uses; poses go through
// tessera/messages/geometry.hpp.
#pragma once

#include <tessera/msg/common.capnp.h>
#include <tessera/msg/map.capnp.h>
#include <tessera/msg/sensor.capnp.h>
#include <tessera/messages/geometry.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <string_view>

namespace tessera {

inline void setHeader(msg::Header::Builder h, std::int64_t stamp_ns, std::string_view frame,
                      std::uint64_t seq) {
  h.setStampNs(stamp_ns);
  h.setFrameId(capnp::Text::Reader(frame.data(), frame.size()));
  h.setSeq(seq);
}

}  // namespace tessera
