// Random mutations of dataset text for property tests of parsers ("parse or throw DatasetError,
// never crash"). Generic: text in, mutated text out, deterministic for a given seed.
//
//   tessera::test::Mutator m(seed);
//   for (int i = 0; i < 3000; ++i) {
//     const std::string bad = m.mutate(original);
//     try { parse(bad); } catch (const DatasetError&) {}  // anything else fails the test
//   }
//
// Each call applies 1..max_edits edits chosen among: flip/insert/delete a byte, truncate, delete
// or duplicate a whitespace-separated token, swap two tokens, replace a token by a nasty number
// ("nan", "inf", "-inf", "1e999", "-1", huge integers, "", ...), duplicate or delete a line.
#pragma once

#include <cstddef>
#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace tessera::test {

class Mutator {
 public:
  explicit Mutator(std::uint64_t seed, int max_edits = 3) : rng_(seed), max_edits_(max_edits) {}

  std::string mutate(std::string text) {
    const int edits = uniform(1, max_edits_);
    for (int e = 0; e < edits; ++e) text = edit(std::move(text));
    return text;
  }

  // Numbers and words that tend to break parsers.
  static const std::vector<std::string>& nastyTokens() {
    static const std::vector<std::string> tokens = {"nan",
                                                    "NaN",
                                                    "-nan",
                                                    "inf",
                                                    "-inf",
                                                    "infinity",
                                                    "1e999",
                                                    "-1e999",
                                                    "1e-999",
                                                    "-1",
                                                    "0",
                                                    "-0",
                                                    "4294967296",
                                                    "9223372036854775807",
                                                    "9223372036854775808",
                                                    "-9223372036854775808",
                                                    "18446744073709551615",
                                                    "99999999999999999999999",
                                                    "1e308",
                                                    "2147483647",
                                                    "-2147483648",
                                                    "0x10",
                                                    "1.5.5",
                                                    "+",
                                                    "-",
                                                    ".",
                                                    "e5",
                                                    "1e",
                                                    "#",
                                                    "\t",
                                                    "1000000000"};
    return tokens;
  }

 private:
  int uniform(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
  std::size_t index(std::size_t n) {
    return n == 0 ? 0 : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng_);
  }

  // [begin, end) of whitespace-separated tokens.
  static std::vector<std::pair<std::size_t, std::size_t>> tokens(const std::string& s) {
    std::vector<std::pair<std::size_t, std::size_t>> out;
    std::size_t i = 0;
    const auto space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
    while (i < s.size()) {
      while (i < s.size() && space(s[i])) ++i;
      const std::size_t b = i;
      while (i < s.size() && !space(s[i])) ++i;
      if (i > b) out.emplace_back(b, i);
    }
    return out;
  }

  // [begin, end) of lines, newline included.
  static std::vector<std::pair<std::size_t, std::size_t>> lines(const std::string& s) {
    std::vector<std::pair<std::size_t, std::size_t>> out;
    std::size_t b = 0;
    while (b < s.size()) {
      std::size_t e = s.find('\n', b);
      e = e == std::string::npos ? s.size() : e + 1;
      out.emplace_back(b, e);
      b = e;
    }
    return out;
  }

  std::string edit(std::string s) {
    if (s.empty()) return std::string(1, static_cast<char>(uniform(0, 255)));
    switch (uniform(0, 10)) {
      case 0:  // flip a byte
        s[index(s.size())] = static_cast<char>(uniform(0, 255));
        return s;
      case 1:  // insert a byte
        s.insert(s.begin() + static_cast<std::ptrdiff_t>(index(s.size() + 1)),
                 static_cast<char>(uniform(0, 255)));
        return s;
      case 2:  // delete a byte
        s.erase(index(s.size()), 1);
        return s;
      case 3:  // truncate
        s.resize(index(s.size()));
        return s;
      default:
        break;
    }
    const auto toks = tokens(s);
    if (toks.empty()) return s;
    const auto [b, e] = toks[index(toks.size())];
    switch (uniform(4, 10)) {
      case 4:  // delete a token
        s.erase(b, e - b);
        return s;
      case 5: {  // duplicate a token
        std::string copy(1, ' ');
        copy.append(s, b, e - b);
        s.insert(e, copy);
        return s;
      }
      case 6: {  // swap with another token
        const auto [b2, e2] = toks[index(toks.size())];
        if (b2 == b) return s;
        const auto [fb, fe] = b < b2 ? std::pair(b, e) : std::pair(b2, e2);
        const auto [sb, se] = b < b2 ? std::pair(b2, e2) : std::pair(b, e);
        const std::string first = s.substr(fb, fe - fb), second = s.substr(sb, se - sb);
        s.replace(sb, se - sb, first);
        s.replace(fb, fe - fb, second);
        return s;
      }
      case 7:
      case 8: {  // replace a token by a nasty value
        const auto& nasty = nastyTokens();
        s.replace(b, e - b, nasty[index(nasty.size())]);
        return s;
      }
      case 9: {  // duplicate a line
        const auto ls = lines(s);
        const auto [lb, le] = ls[index(ls.size())];
        std::string copy = s.substr(lb, le - lb);
        if (copy.empty() || copy.back() != '\n') copy.push_back('\n');
        s.insert(lb, copy);
        return s;
      }
      default: {  // delete a line
        const auto ls = lines(s);
        const auto [lb, le] = ls[index(ls.size())];
        s.erase(lb, le - lb);
        return s;
      }
    }
  }

  std::mt19937_64 rng_;
  int max_edits_;
};

}  // namespace tessera::test
