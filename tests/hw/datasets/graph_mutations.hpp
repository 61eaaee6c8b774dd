// Random mutations of a text dataset for robustness tests: a parser fed the result must either
// succeed or throw DatasetError. Minimal on purpose (h/laser has a fuller tests/hw/datasets/
// mutate.hpp; the two should be unified).
#pragma once

#include <cstddef>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace tessera::test {

namespace detail {
// [begin, end) of each whitespace-separated token.
inline std::vector<std::pair<std::size_t, std::size_t>> tokenSpans(const std::string& s) {
  std::vector<std::pair<std::size_t, std::size_t>> spans;
  std::size_t i = 0;
  auto space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
  while (i < s.size()) {
    while (i < s.size() && space(s[i])) ++i;
    const std::size_t b = i;
    while (i < s.size() && !space(s[i])) ++i;
    if (i > b) spans.emplace_back(b, i);
  }
  return spans;
}
}  // namespace detail

// Applies one random mutation: byte flip, truncation, token deletion / duplication, a token
// replaced by a hostile number, or a line deleted / duplicated.
inline std::string mutateOnce(std::string s, std::mt19937_64& rng) {
  static const std::vector<std::string> kHostile = {"nan",
                                                    "NaN",
                                                    "inf",
                                                    "-inf",
                                                    "1e999",
                                                    "-1e999",
                                                    "-1",
                                                    "0",
                                                    "-0",
                                                    "1e-320",
                                                    "99999999999999999999",
                                                    "2147483648",
                                                    "-2147483649",
                                                    "9223372036854775807",
                                                    "0x1p3",
                                                    "",
                                                    "1e308",
                                                    "-1e308",
                                                    "#",
                                                    "EDGE_SE2",
                                                    "VERTEX2",
                                                    "FIX"};
  auto pick = [&rng](std::size_t n) {
    return std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
  };
  if (s.empty()) return "x";
  const auto spans = detail::tokenSpans(s);
  switch (pick(7)) {
    case 0: {  // byte flip (including NUL and newline)
      s[pick(s.size())] = static_cast<char>(pick(256));
      return s;
    }
    case 1:  // truncation
      return s.substr(0, pick(s.size()));
    case 2: {  // token deletion
      if (spans.empty()) return s;
      const auto [b, e] = spans[pick(spans.size())];
      return s.erase(b, e - b);
    }
    case 3: {  // token duplication
      if (spans.empty()) return s;
      const auto [b, e] = spans[pick(spans.size())];
      return s.insert(e, " " + s.substr(b, e - b));
    }
    case 4:
    case 5: {  // hostile number
      if (spans.empty()) return s;
      const auto [b, e] = spans[pick(spans.size())];
      return s.replace(b, e - b, kHostile[pick(kHostile.size())]);
    }
    default: {  // delete or duplicate a whole line
      std::size_t b = pick(s.size());
      b = s.rfind('\n', b);
      b = b == std::string::npos ? 0 : b + 1;
      std::size_t e = s.find('\n', b);
      e = e == std::string::npos ? s.size() : e + 1;
      if (pick(2) == 0) return s.erase(b, e - b);
      return s.insert(e, s.substr(b, e - b));
    }
  }
}

// One to three mutations.
inline std::string mutate(std::string s, std::mt19937_64& rng) {
  const int n = std::uniform_int_distribution<int>(1, 3)(rng);
  for (int i = 0; i < n; ++i) s = mutateOnce(std::move(s), rng);
  return s;
}

}  // namespace tessera::test
