// brume — sampled effect parameters keyed by (seed, frame key, parameter
// name); the scheme, its Python twin and the checks are in brume/sample.hpp.
#include "brume/sample.hpp"

#include <openssl/evp.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "core/text.hpp"

namespace brume {

namespace {

// Shortest text that reads back as the same double ("50", "0.8", "1e-05").
std::string shortest(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

using text::lower;
using text::parse_number;
using text::trim;

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

// seed() draws in [0, 2^53).
constexpr std::uint64_t kSeedDrawEnd = std::uint64_t{1} << 53;

const char* kAllowed =
    "a fixed value as the flag takes it (0.9, auto, a name), uniform(a, b), loguniform(a, b) with 0 < a, "
    "choice(x, y, ...), or seed() (a whole number per key)";

// An effect's sampling, from its entry in the list of commands
// (CommandDef::sampling; the default ranges and their reasons are in each
// effect's definition). A default is dropped when the user gives one of its
// `dropped_by` (a parameter that takes over its role, so that the pair would
// be refused by validate_<effect>).
struct EffectSampling {
  std::string effect;
  const CommandSampling* s = nullptr;
  const std::vector<ParamSpec>& specs() const { return s->specs; }
};

const std::vector<EffectSampling>& samplings() {
  static const std::vector<EffectSampling> all = [] {
    std::vector<EffectSampling> v;
    for (const CommandDef& c : commands())
      if (c.sampling) v.push_back({c.name, &*c.sampling});
    return v;
  }();
  return all;
}

const EffectSampling& sampling_of(std::string_view effect) {
  for (const EffectSampling& s : samplings())
    if (s.effect == effect) return s;
  std::string all;
  for (const EffectSampling& s : samplings()) all += (all.empty() ? "" : ", ") + s.effect;
  throw Error("sampling: effect '" + std::string(effect) + "' has no sampled parameters; use one of: " + all);
}

const ParamSpec& spec_of(const EffectSampling& s, const std::string& canon) {
  for (const ParamSpec& p : s.specs())
    if (p.name == canon) return p;
  throw Error("internal: sampling: no declaration of '" + canon + "' in " + s.effect);
}

// Splits "a, b, c" at commas; items trimmed.
std::vector<std::string> split_args(const std::string& s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (std::size_t i = 0; i <= s.size(); ++i)
    if (i == s.size() || s[i] == ',') {
      out.push_back(trim(std::string_view(s).substr(start, i - start)));
      start = i + 1;
    }
  return out;
}

std::map<std::string, Distribution> resolve(const EffectSampling& es, const std::map<std::string, std::string>& specs) {
  std::map<std::string, std::string> user;  // canonical name -> text
  std::map<std::string, std::string> spelled;
  for (const auto& [name, text] : specs) {
    std::string canon;
    try {
      canon = detail::canonical_param_name(es.specs(), name, es.effect);
    } catch (const Error& e) {
      // A parameter of another effect (visibility given for fog) says so: the fix is the effect, not the spelling.
      std::string others;
      for (const EffectSampling& o : samplings()) {
        if (o.effect == es.effect) continue;
        try {
          detail::canonical_param_name(o.specs(), name, o.effect);
          others += (others.empty() ? "" : ", ") + o.effect;
        } catch (const Error&) {
        }
      }
      if (others.empty()) throw;
      throw Error(std::string(e.what()) + "; '" + name + "' is a parameter of " + others);
    }
    if (user.count(canon))
      throw Error("sampling " + es.effect + ": '" + spelled[canon] + "' and '" + name + "' are the same parameter ('" +
                  canon + "'); give it once");
    user[canon] = text;
    spelled[canon] = name;
  }
  std::map<std::string, Distribution> out;
  for (const SampleDefault& d : es.s->defaults) {
    if (user.count(d.name)) continue;
    const bool dropped = std::any_of(d.dropped_by.begin(), d.dropped_by.end(), [&](const std::string& rule) {
      // "name": given at all; "name=v": given as the fixed value v; "name!=v": given as anything but v.
      const std::size_t eq = rule.find('=');
      if (eq == std::string::npos) return user.count(rule) > 0;
      const bool negated = eq > 0 && rule[eq - 1] == '!';
      const std::string name = rule.substr(0, negated ? eq - 1 : eq), value = rule.substr(eq + 1);
      const auto it = user.find(name);
      if (it == user.end()) return false;
      // The same value however it is written (0, 0.0): compared as the declaration parses it.
      const ParamSpec& spec = spec_of(es, name);
      bool same = trim(it->second) == value;
      try {
        const Distribution given = parse_distribution(spec, it->second);
        same = given.kind == Distribution::Kind::fixed && given.values.at(0) == spec.parse(value);
      } catch (const Error&) {
      }
      return same != negated;
    });
    if (!dropped) out[d.name] = parse_distribution(spec_of(es, d.name), d.spec);
  }
  for (const auto& [canon, text] : user) out[canon] = parse_distribution(spec_of(es, canon), text);
  return out;
}

}  // namespace

std::uint64_t sha256_prefix64(std::string_view msg) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  if (!ctx || EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) != 1 ||
      EVP_DigestUpdate(ctx, msg.data(), msg.size()) != 1 || EVP_DigestFinal_ex(ctx, md, &len) != 1 || len < 8) {
    EVP_MD_CTX_free(ctx);
    throw Error("internal: SHA-256 (OpenSSL) failed");
  }
  EVP_MD_CTX_free(ctx);
  std::uint64_t n = 0;
  for (int i = 0; i < 8; ++i) n = (n << 8) | md[i];
  return n;
}

double sample_unit(std::uint64_t seed, std::string_view key, std::string_view name) {
  std::string msg = kSamplerName;
  msg.push_back('\0');
  msg += std::to_string(seed);
  msg.push_back('\0');
  msg.append(key.data(), key.size());
  msg.push_back('\0');
  msg.append(name.data(), name.size());
  const std::uint64_t n = sha256_prefix64(msg);
  // The top 53 bits: every double of the form k 2^-53, so u < 1 exactly.
  return static_cast<double>(n >> 11) * 0x1p-53;
}

std::string Distribution::text() const {
  switch (kind) {
    case Kind::uniform: return "uniform(" + shortest(a) + ", " + shortest(b) + ")";
    case Kind::loguniform: return "loguniform(" + shortest(a) + ", " + shortest(b) + ")";
    case Kind::choice:
    case Kind::fixed: {
      std::string s;
      for (const nlohmann::json& v : values) {
        std::string t;
        if (v.is_null()) t = "auto";
        else if (v.is_string()) t = v.get<std::string>();
        else if (v.is_number_float()) t = shortest(v.get<double>());
        else if (v.is_array()) {
          for (const auto& c : v) t += (t.empty() ? "" : ",") + shortest(c.get<double>());
        } else t = v.dump();
        s += (s.empty() ? "" : ", ") + t;
      }
      return kind == Kind::choice ? "choice(" + s + ")" : s;
    }
    case Kind::seed: return "seed()";
  }
  return "";
}

Distribution parse_distribution(const ParamSpec& spec, std::string_view text_in) {
  const std::string text = trim(text_in);
  const std::string flag = "--" + spec.name;
  const std::string where = "sampling " + flag + " '" + std::string(text_in) + "'";
  auto fail = [&](const std::string& why) -> Distribution { throw Error(where + ": " + why); };
  // Every value the distribution can give goes through the declaration's own check.
  auto checked = [&](const nlohmann::json& v, const std::string& role) {
    try {
      spec.check(v);
    } catch (const Error& e) {
      // A constant: the declaration's own message names the value already.
      throw Error(where + ": " + (role.empty() ? std::string() : role + " is not allowed: ") + e.what());
    }
    return v;
  };
  auto parsed = [&](const std::string& item, const std::string& role) {
    nlohmann::json v;
    try {
      v = spec.parse(item);
    } catch (const Error& e) {
      throw Error(where + ": " + e.what());
    }
    return checked(v, role.empty() ? role : role + " '" + item + "'");
  };

  Distribution d;
  if (text.empty()) return fail(std::string("empty; give ") + kAllowed);
  const auto open = text.find('(');
  std::string fn = open == std::string::npos ? "" : lower(trim(std::string_view(text).substr(0, open)));
  // A call is one of the three distributions; any other word( is refused as a misspelt one, except for a text
  // parameter (a file name may hold parentheses).
  const bool known = fn == "uniform" || fn == "loguniform" || fn == "choice" || fn == "seed";
  const bool wordy = !fn.empty() && spec.kind != ParamKind::text &&
                     std::all_of(fn.begin(), fn.end(), [](char c) { return std::isalpha(static_cast<unsigned char>(c)); });
  if (open == std::string::npos || !(known || wordy)) {
    d.kind = Distribution::Kind::fixed;
    d.values.push_back(parsed(text, ""));
    return d;
  }
  if (text.back() != ')') return fail("missing the closing ')'; " + std::string(kAllowed));
  if (fn != "uniform" && fn != "loguniform" && fn != "choice" && fn != "seed")
    return fail("'" + fn + "' is not a distribution; use " + kAllowed);
  const std::string inner = text.substr(open + 1, text.size() - open - 2);
  if (inner.find_first_of("()") != std::string::npos) return fail("nested parentheses are not allowed");
  const std::vector<std::string> args = split_args(inner);

  if (fn == "seed") {
    if (spec.kind != ParamKind::integer)
      return fail("seed() draws a whole number per key, and " + flag + " is not one; use " + kAllowed);
    if (!(args.size() == 1 && args[0].empty())) return fail("seed() takes no arguments: write seed()");
    checked(nlohmann::json(std::uint64_t{0}), "its lowest value 0");
    checked(nlohmann::json(kSeedDrawEnd - 1), "its highest value 2^53 - 1");
    d.kind = Distribution::Kind::seed;
    return d;
  }

  if (fn == "choice") {
    if (spec.kind == ParamKind::rgb)
      return fail("choice(...) of colours is not supported (their commas would be ambiguous); give one R,G,B");
    if (args.size() == 1 && args[0].empty()) return fail("choice() needs at least one item: choice(x, y, ...)");
    d.kind = Distribution::Kind::choice;
    for (const std::string& a : args) {
      if (a.empty()) return fail("an item of choice(...) is empty; write choice(x, y, ...)");
      d.values.push_back(parsed(a, "the item"));
    }
    return d;
  }

  // uniform / loguniform: real parameters only.
  if (spec.kind != ParamKind::real)
    return fail(fn + "(a, b) draws real numbers, and " + flag + " is " +
                (spec.kind == ParamKind::integer ? "a whole number" : spec.kind == ParamKind::choice ? "a name" : "not a number") +
                "; use choice(...) or a fixed value");
  if (args.size() != 2) return fail(fn + " takes two bounds, " + fn + "(a, b); got " + std::to_string(args.size()));
  double a = 0, b = 0;
  if (!parse_number(args[0], a) || !std::isfinite(a)) return fail("the lower bound '" + args[0] + "' is not a finite number");
  if (!parse_number(args[1], b) || !std::isfinite(b)) return fail("the upper bound '" + args[1] + "' is not a finite number");
  if (!(a < b))
    return fail("the bounds need a < b (got " + shortest(a) + " and " + shortest(b) + "); for a constant give the value alone");
  if (fn == "loguniform" && !(a > 0))
    return fail("loguniform needs 0 < a (log-uniform over positive values); got a = " + shortest(a) + "; use uniform(a, b)");
  // The draws lie in [a, b): both ends must be admissible values.
  checked(a, "its lower bound " + shortest(a));
  checked(b, "its upper bound " + shortest(b));
  d.kind = fn == "uniform" ? Distribution::Kind::uniform : Distribution::Kind::loguniform;
  d.a = a, d.b = b;
  return d;
}

nlohmann::json draw(const Distribution& d, double u) {
  switch (d.kind) {
    case Distribution::Kind::fixed: return d.values.at(0);
    case Distribution::Kind::uniform:
      // Held to [a, b] against the last ulp of rounding (a + u (b - a) may round up to b, never past it by more).
      return std::clamp(d.a + u * (d.b - d.a), d.a, d.b);
    case Distribution::Kind::loguniform: {
      const double la = std::log(d.a), lb = std::log(d.b);
      return std::clamp(std::exp(la + u * (lb - la)), d.a, d.b);
    }
    case Distribution::Kind::choice: {
      const std::size_t n = d.values.size();
      const std::size_t i = std::min(n - 1, static_cast<std::size_t>(u * static_cast<double>(n)));
      return d.values[i];
    }
    case Distribution::Kind::seed:
      // u = k·2^-53 exactly (sample_unit): k, the hash's top 53 bits.
      return std::min(static_cast<std::uint64_t>(u * 0x1p53), kSeedDrawEnd - 1);
  }
  return nullptr;
}

const std::vector<std::string>& sample_effects() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const EffectSampling& s : samplings()) n.push_back(s.effect);
    return n;
  }();
  return names;
}

std::map<std::string, std::string> resolve_sample_specs(std::string_view effect,
                                                        const std::map<std::string, std::string>& specs) {
  std::map<std::string, std::string> out;
  for (const auto& [name, d] : resolve(sampling_of(effect), specs)) out[name] = d.text();
  return out;
}

nlohmann::json random_params(std::string_view effect, std::uint64_t seed, std::string_view key,
                             const std::map<std::string, std::string>& specs) {
  const EffectSampling& es = sampling_of(effect);
  nlohmann::json values = nlohmann::json::object();
  for (const auto& [name, d] : resolve(es, specs))
    values[name] = d.kind == Distribution::Kind::fixed ? d.values.at(0) : draw(d, sample_unit(seed, key, name));
  try {
    es.s->validate(values);
  } catch (const Error& e) {
    // A value may hold bytes that are not UTF-8 (a text parameter as typed):
    // the message shows them as U+FFFD rather than failing to be written
    // (found by fuzz/fuzz_sample_specs.cpp; reproducer in its corpus).
    throw Error("sampled " + es.effect + " parameters " +
                values.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + " for key '" +
                std::string(key) + "' (seed " +
                std::to_string(seed) + ") cannot be used together: " + e.what());
  }
  return values;
}

std::vector<nlohmann::json> sample_corners(std::string_view effect, const std::map<std::string, std::string>& specs,
                                           std::size_t max) {
  const EffectSampling& es = sampling_of(effect);
  std::vector<std::pair<std::string, std::vector<nlohmann::json>>> ends;
  std::size_t n = 1;
  for (const auto& [name, d] : resolve(es, specs)) {
    std::vector<nlohmann::json> v;
    switch (d.kind) {
      case Distribution::Kind::fixed: v = {d.values.at(0)}; break;
      case Distribution::Kind::uniform:
      case Distribution::Kind::loguniform: v = {d.a, d.b}; break;
      case Distribution::Kind::choice: v = d.values; break;
      case Distribution::Kind::seed: v = {std::uint64_t{0}, kSeedDrawEnd - 1}; break;
    }
    n *= v.size();
    if (n > max)
      throw Error("sampling " + es.effect + ": the distributions' ends make more than " + std::to_string(max) +
                  " combinations to check; give fewer choices");
    ends.emplace_back(name, std::move(v));
  }
  std::vector<nlohmann::json> out;
  for (std::size_t i = 0; i < n; ++i) {
    nlohmann::json set = nlohmann::json::object();
    std::size_t rest = i;
    for (const auto& [name, v] : ends) {
      set[name] = v[rest % v.size()];
      rest /= v.size();
    }
    out.push_back(std::move(set));
  }
  return out;
}

nlohmann::json sample_provenance(std::string_view effect, std::uint64_t seed, std::string_view key,
                                 const std::map<std::string, std::string>& specs) {
  return {{"sampler", kSamplerName},
          {"seed", seed},
          {"key", std::string(key)},
          {"specs", resolve_sample_specs(effect, specs)}};
}

namespace detail {

std::string canonical_param_name(const std::vector<ParamSpec>& specs, std::string_view name_in, std::string_view where) {
  std::string name = trim(name_in);
  // Python keywords: lambda_ (PEP 8's escape of a reserved word) and kappa_s for kappa-s.
  if (name.size() > 1 && name.back() == '_') name.pop_back();
  std::replace(name.begin(), name.end(), '_', '-');
  for (const ParamSpec& s : specs) {
    if (s.name == name) return s.name;
    for (const std::string& a : s.aliases)
      if (a == name) return s.name;
  }
  std::string nearest;
  std::size_t best = std::string::npos;
  for (const ParamSpec& s : specs) {
    const std::size_t dist = edit_distance(name, s.name);
    if (dist < best) best = dist, nearest = s.name;
  }
  std::string all;
  for (const ParamSpec& s : specs) all += (all.empty() ? "" : ", ") + s.name;
  throw Error("'" + std::string(name_in) + "' is not a parameter of " + std::string(where) +
              (nearest.empty() ? "" : "; did you mean '" + nearest + "'?") + " (its parameters: " + all + ")");
}

}  // namespace detail

}  // namespace brume
