#include <tessera/datasets/relations.hpp>

#include <cmath>
#include <string>

namespace tessera::datasets {

using io::Fields;
using io::TextReader;
namespace {

// Seconds to nanoseconds. Relation stamps are ~1e9 s with 6 decimals; a double holds them to
// ~0.1 µs, far below the spacing of any trajectory they are compared with.
std::int64_t toNanoseconds(const Fields& fields, std::size_t i, const char* label) {
  const double s = fields.real(i, label);
  // int64 nanoseconds cover ±292 years; beyond that the value cannot be a time stamp.
  if (std::abs(s) > 9.2e9)
    fields.fail("field " + std::to_string(i + 1) + " (" + label +
                "): time stamp out of range, got '" + std::string(fields[i]) + "'");
  return std::llround(s * 1e9);
}

}  // namespace

RelationsFile readRelations(const std::filesystem::path& path) {
  TextReader reader(path);
  return readRelations(reader);
}

RelationsFile readRelations(TextReader& reader) {
  RelationsFile out;
  std::string line;
  while (reader.next(line)) {
    ++out.report.lines;
    const Fields f(reader, line);
    if (f.empty() || f[0].front() == '#') continue;
    f.requireExactly(8, "relation 't1 t2 dx dy dz roll pitch yaw'");
    Relation r;
    r.t1_ns = toNanoseconds(f, 0, "t1");
    r.t2_ns = toNanoseconds(f, 1, "t2");
    r.dx = f.real(2, "dx");
    r.dy = f.real(3, "dy");
    r.dz = f.real(4, "dz");
    r.roll = f.real(5, "roll");
    r.pitch = f.real(6, "pitch");
    r.yaw = f.real(7, "yaw");
    out.relations.push_back(r);
    ++out.report.records;
  }
  return out;
}

}  // namespace tessera::datasets
