// Zero-copy views over Cap'n Proto list and data fields: std::span and Eigen::Map that point
// straight into the message bytes. Views live as long as the Message/Loan they came from.
// Cap'n Proto stores primitives little-endian and word-aligned, which is the host layout on
// every platform Tessera supports (x86-64, aarch64), so reinterpretation is exact.
#pragma once

#include <capnp/any.h>
#include <capnp/blob.h>
#include <capnp/list.h>

#include <Eigen/Core>

#include <cstdint>
#include <span>

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "Tessera's message views need little-endian");

namespace tessera {

/// Read-only view of a primitive list (List(Float32), List(Float64), List(Int32)...).
template <typename E>
std::span<const E> view(typename capnp::List<E>::Reader list) {
  auto bytes = capnp::AnyList::Reader(list).getRawBytes();
  return {reinterpret_cast<const E*>(bytes.begin()), list.size()};
}

/// Writable view of a primitive list being built (fill ranges without per-element setters).
template <typename E>
std::span<E> mutableView(typename capnp::List<E>::Builder list) {
  // AnyList::Builder has no raw-bytes accessor in Cap'n Proto 0.9; the reader of a builder points
  // into the same writable segment, so dropping const here is sound.
  auto bytes = capnp::AnyList::Reader(list.asReader()).getRawBytes();
  return {reinterpret_cast<E*>(const_cast<capnp::byte*>(bytes.begin())), list.size()};
}

/// Read-only view of a Data field as signed bytes (e.g. occupancy cells).
inline std::span<const std::int8_t> viewInt8(capnp::Data::Reader data) {
  return {reinterpret_cast<const std::int8_t*>(data.begin()), data.size()};
}
inline std::span<std::int8_t> mutableViewInt8(capnp::Data::Builder data) {
  return {reinterpret_cast<std::int8_t*>(data.begin()), data.size()};
}

/// Eigen view of a List(Float32) / List(Float64) as a column vector.
inline Eigen::Map<const Eigen::VectorXf> eigenView(capnp::List<float>::Reader list) {
  auto s = view<float>(list);
  return {s.data(), static_cast<Eigen::Index>(s.size())};
}
inline Eigen::Map<const Eigen::VectorXd> eigenView(capnp::List<double>::Reader list) {
  auto s = view<double>(list);
  return {s.data(), static_cast<Eigen::Index>(s.size())};
}

}  // namespace tessera
