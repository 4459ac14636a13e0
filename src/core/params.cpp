// brume — typed parameter declarations (see brume/params.hpp): parsing what a
// user typed, checking a value, and describing a parameter.
#include "brume/params.hpp"
#include "core/text.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

namespace brume {

namespace {

// strtod over the whole text ("1e-3", "inf", "nan"), nothing left over.
using text::parse_number;

// A ratio of two finite numbers, "1/3" or "30000/1001", as a real flag's
// value (Middlebury's third-size disparities are scaled by 1/3): p / q with q
// != 0. The quotient is what the record keeps.
bool parse_ratio(const std::string& t, double& v) {
  const std::size_t slash = t.find('/');
  if (slash == std::string::npos || t.find('/', slash + 1) != std::string::npos) return false;
  double p = 0, q = 0;
  if (!parse_number(t.substr(0, slash), p) || !parse_number(t.substr(slash + 1), q)) return false;
  if (!std::isfinite(p) || !std::isfinite(q) || q == 0.0) return false;
  v = p / q;
  return true;
}

}  // namespace

std::size_t first_invalid_utf8(const std::string& s) {
  const std::size_t n = s.size();
  std::size_t i = 0;
  while (i < n) {
    const unsigned c = static_cast<unsigned char>(s[i]);
    if (c < 0x80) {
      ++i;
      continue;
    }
    // The lead byte fixes the length and the range of the second byte
    // (RFC 3629 table 3-7): E0 and F0 exclude overlong forms, ED the UTF-16
    // surrogates, F4 anything above U+10FFFF.
    std::size_t len = 0;
    unsigned lo = 0x80, hi = 0xBF;
    if (c >= 0xC2 && c <= 0xDF) len = 2;
    else if (c == 0xE0) len = 3, lo = 0xA0;
    else if ((c >= 0xE1 && c <= 0xEC) || c == 0xEE || c == 0xEF) len = 3;
    else if (c == 0xED) len = 3, hi = 0x9F;
    else if (c == 0xF0) len = 4, lo = 0x90;
    else if (c >= 0xF1 && c <= 0xF3) len = 4;
    else if (c == 0xF4) len = 4, hi = 0x8F;
    else return i;
    if (n - i < len) return i;
    const unsigned c1 = static_cast<unsigned char>(s[i + 1]);
    if (c1 < lo || c1 > hi) return i;
    for (std::size_t k = 2; k < len; ++k) {
      const unsigned ck = static_cast<unsigned char>(s[i + k]);
      if (ck < 0x80 || ck > 0xBF) return i;
    }
    i += len;
  }
  return std::string::npos;
}

std::string printable_text(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  char hex[8];
  std::size_t i = 0;
  while (i < text.size()) {
    const std::string rest(text.substr(i));
    const std::size_t bad = first_invalid_utf8(rest);
    const std::size_t good = bad == std::string::npos ? rest.size() : bad;
    for (std::size_t k = 0; k < good; ++k) {
      const unsigned char c = static_cast<unsigned char>(rest[k]);
      if ((c < 0x20 && c != '\n' && c != '\t') || c == 0x7F) {
        std::snprintf(hex, sizeof hex, "\\x%02X", c);
        out += hex;
      } else {
        out += static_cast<char>(c);
      }
    }
    if (bad == std::string::npos) break;
    std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned char>(rest[bad]));
    out += hex;
    i += bad + 1;
  }
  return out;
}

void check_utf8(const std::string& text, const std::string& what) {
  std::size_t bad = first_invalid_utf8(text);
  if (bad == std::string::npos) return;
  const unsigned first = static_cast<unsigned char>(text[bad]);
  // The value as typed, with every byte that breaks the encoding as \xHH.
  std::string shown;
  std::size_t i = 0;
  char hex[8];
  while (i < text.size()) {
    const std::size_t j = first_invalid_utf8(text.substr(i));
    if (j == std::string::npos) {
      shown += text.substr(i);
      break;
    }
    shown += text.substr(i, j);
    std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned char>(text[i + j]));
    shown += hex;
    i += j + 1;
  }
  std::snprintf(hex, sizeof hex, "0x%02X", first);
  throw Error(what + " '" + shown + "' is not valid UTF-8 (byte " + hex + " at offset " + std::to_string(bad) +
              "): brume writes every path, key and argument into its JSON records and manifests, which hold "
              "UTF-8 text only; rename the file to a UTF-8 name (e.g. convmv -f latin1 -t utf8 --notest FILE) "
              "or pass a symbolic link that has one");
}

bool Range::contains(double v) const {
  if (std::isnan(v)) return false;
  const bool lo = min_open ? v > min : v >= min;
  const bool hi = max_open ? v < max : v <= max;
  return lo && hi;
}

std::string Range::text() const {
  return std::string(min_open || std::isinf(min) ? "(" : "[") + text::g(min) + ", " + text::g(max) +
         (max_open || std::isinf(max) ? ")" : "]");
}

std::string ParamSpec::format(const nlohmann::json& v) const {
  if (v.is_null()) return unset_word;
  if ((kind == ParamKind::rgb || kind == ParamKind::real) && v.is_string()) return v.get<std::string>();  // a word
  switch (kind) {
    case ParamKind::real: return text::g(v.get<double>());
    case ParamKind::integer: return v.dump();
    case ParamKind::boolean: return v.get<bool>() ? "true" : "false";
    case ParamKind::rgb: {
      const Rgb c = v.get<Rgb>();
      return text::g(c[0]) + "," + text::g(c[1]) + "," + text::g(c[2]);
    }
    case ParamKind::pair: {
      const Pair c = v.get<Pair>();
      return text::g(c[0]) + "," + text::g(c[1]);
    }
    case ParamKind::choice:
    case ParamKind::text: return v.get<std::string>();
  }
  return v.dump();
}

std::string ParamSpec::describe() const {
  std::ostringstream m;
  m << help;
  switch (kind) {
    case ParamKind::real:
    case ParamKind::integer:
      m << " [" << (unit.empty() ? "" : unit + ", ") << range.text();
      for (const std::string& w : words) m << " | " << w;
      m << "]";
      break;
    case ParamKind::rgb:
      m << " [" << (unit.empty() ? "" : unit + ", ") << "R,G,B each in " << range.text();
      for (const std::string& w : words) m << " | " << w;
      m << "]";
      break;
    case ParamKind::pair:
      m << " [" << (unit.empty() ? "" : unit + ", ") << "X,Y each in " << range.text() << "]";
      break;
    case ParamKind::choice: {
      m << " [";
      for (std::size_t i = 0; i < choices.size(); ++i) m << (i ? "|" : "") << choices[i];
      m << "]";
      break;
    }
    default: break;
  }
  if (optional) m << " ('" << unset_word << "' to leave unset)";
  return m.str();
}

nlohmann::json ParamSpec::parse(const std::string& t) const {
  const std::string flag = "--" + name;
  if (optional && t == unset_word) return nullptr;
  switch (kind) {
    case ParamKind::real: {
      for (const std::string& w : words)
        if (t == w) return t;
      double v = 0;
      if (!parse_number(t, v) && !parse_ratio(t, v))
        throw Error(flag + " '" + t + "' is not a number" + (optional ? " (or " + unset_word + ")" : "") + "; " +
                    describe());
      return v;
    }
    case ParamKind::integer: {
      char* end = nullptr;
      const long long v = std::strtoll(t.c_str(), &end, 10);
      if (t.empty() || end != t.c_str() + t.size())
        throw Error(flag + " '" + t + "' is not a whole number; " + describe());
      return v;
    }
    case ParamKind::boolean:
      if (t == "true" || t == "1" || t == "yes" || t == "on") return true;
      if (t == "false" || t == "0" || t == "no" || t == "off") return false;
      throw Error(flag + " '" + t + "' is not true or false");
    case ParamKind::choice: return t;  // checked against the name table by check()
    case ParamKind::rgb: {
      std::string word_list;  // ", horizon": the names it also takes
      for (const std::string& w : words) {
        if (t == w) return t;
        word_list += ", " + w;
      }
      Rgb c{};
      std::stringstream ss(t);
      std::string item;
      int n = 0;
      while (std::getline(ss, item, ',')) {
        double v = 0;
        if (n < 3 && !parse_number(item, v))
          throw Error(flag + " '" + t + "': '" + item + "' is not a number; give R,G,B in linear light, e.g. "
                      "0.8,0.82,0.85" + word_list + (optional ? ", or " + unset_word : std::string()));
        if (n < 3) c[n] = static_cast<float>(v);
        ++n;
      }
      if (n != 3)
        throw Error(flag + " '" + t + "' must be three comma-separated numbers R,G,B (linear light)" + word_list +
                    (optional ? " or " + unset_word : std::string()));
      return c;
    }
    case ParamKind::pair: {
      Pair c{};
      std::stringstream ss(t);
      std::string item;
      int n = 0;
      while (std::getline(ss, item, ',')) {
        double v = 0;
        if (n < 2 && !parse_number(item, v))
          throw Error(flag + " '" + t + "': '" + item + "' is not a number; give X,Y, e.g. 0,0.1; " + describe());
        if (n < 2) c[n] = v;
        ++n;
      }
      if (n != 2 || (!t.empty() && t.back() == ','))
        throw Error(flag + " '" + t + "' must be two comma-separated numbers X,Y; " + describe());
      return c;
    }
    case ParamKind::text: return t;
  }
  return t;
}

void ParamSpec::check(const nlohmann::json& v) const {
  const std::string flag = "--" + name;
  if (v.is_null()) {
    if (optional) return;
    throw Error(flag + " has no value; it must be given (" + describe() + ")");
  }
  auto bad_type = [&](const char* what) {
    throw Error(flag + " " + v.dump() + " is not " + what + "; " + describe());
  };
  switch (kind) {
    case ParamKind::real: {
      if (v.is_string() && !words.empty()) {
        for (const std::string& w : words)
          if (v.get<std::string>() == w) return;
        std::string all;
        for (const std::string& w : words) all += ", " + w;
        throw Error(flag + " '" + v.get<std::string>() + "' is not allowed; give a number in " + range.text() + all +
                    (optional ? " or " + unset_word : std::string()));
      }
      if (!v.is_number()) bad_type("a number");
      const double x = v.get<double>();
      if (!std::isfinite(x) && !(allow_inf && x > 0 && std::isinf(x)))
        throw Error(flag + " " + text::g(x) + " is not allowed: it must be a finite number in " + range.text() +
                    (unit.empty() ? "" : " (" + unit + ")") + "; " + help);
      if (!range.contains(x))
        throw Error(flag + " " + text::g(x) + " is not allowed: it must be in " + range.text() +
                    (unit.empty() ? "" : " (" + unit + ")") + "; " + help);
      return;
    }
    case ParamKind::integer: {
      if (!v.is_number_integer()) bad_type("a whole number");
      const double x = static_cast<double>(v.get<long long>());
      if (!range.contains(x))
        throw Error(flag + " " + v.dump() + " is not allowed: it must be a whole number in " + range.text() +
                    (unit.empty() ? "" : " (" + unit + ")") + "; " + help);
      return;
    }
    case ParamKind::boolean:
      if (!v.is_boolean()) bad_type("true or false");
      return;
    case ParamKind::choice: {
      if (!v.is_string()) bad_type("a name");
      const std::string s = v.get<std::string>();
      for (const auto& c : choices)
        if (c == s) return;
      std::string all;
      for (const auto& c : choices) all += (all.empty() ? "" : ", ") + c;
      throw Error(flag + " '" + s + "' is not allowed; use one of: " + all);
    }
    case ParamKind::rgb: {
      if (v.is_string() && !words.empty()) {
        for (const std::string& w : words)
          if (v.get<std::string>() == w) return;
        std::string all;
        for (const std::string& w : words) all += ", " + w;
        throw Error(flag + " '" + v.get<std::string>() + "' is not allowed; give R,G,B (three numbers, linear light)" +
                    all + (optional ? " or " + unset_word : std::string()));
      }
      if (!v.is_array() || v.size() != 3) bad_type("three numbers R,G,B");
      for (const auto& c : v) {
        if (!c.is_number()) bad_type("three numbers R,G,B");
        const double x = c.get<double>();
        if (!std::isfinite(x) || !range.contains(x))
          throw Error(flag + " " + format(v) + ": every component must be finite and in " + range.text() +
                      (unit.empty() ? "" : " (" + unit + ")") + "; " + help);
      }
      return;
    }
    case ParamKind::pair: {
      if (!v.is_array() || v.size() != 2) bad_type("two numbers X,Y");
      for (const auto& c : v) {
        if (!c.is_number()) bad_type("two numbers X,Y");
        const double x = c.get<double>();
        if (!std::isfinite(x) || !range.contains(x))
          throw Error(flag + " " + format(v) + ": both numbers must be finite and in " + range.text() +
                      (unit.empty() ? "" : " (" + unit + ")") + "; " + help);
      }
      return;
    }
    case ParamKind::text:
      if (!v.is_string()) bad_type("text");
      check_utf8(v.get_ref<const std::string&>(), flag);
      return;
  }
}

std::string prefix_flag_mentions(const std::string& text, const std::string& prefix,
                                 const std::function<bool(const std::string&)>& is_flag) {
  const auto word = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0; };
  std::string out;
  std::size_t i = 0;
  while (i < text.size()) {
    if (text.compare(i, 2, "--") == 0 && (i == 0 || !word(text[i - 1]))) {
      std::size_t j = i + 2;
      while (j < text.size() && (word(text[j]) || text[j] == '-')) ++j;
      std::string name = text.substr(i + 2, j - i - 2);
      while (!name.empty() && name.back() == '-') name.pop_back(), --j;  // "--foo-" at a line end
      out += "--" + (is_flag(name) ? prefix : std::string()) + name;
      i = j;
    } else {
      out += text[i++];
    }
  }
  return out;
}

}  // namespace brume
