// brume — sampled effect parameters for data augmentation, keyed by frame.
//
// A dataset builder wants "visibility log-uniform between 50 m and 5 km" per
// frame, and wants frame Art/view1.png to get the same visibility whether it
// is drawn by `brume batch`, by the Python module, on shard 3 of 8 or on a
// Dask worker, in any row order. So a draw is not the next number of a
// generator: it is a pure function of (seed, frame key, parameter name),
//
//   u = H("brume-sample-v1" \0 decimal(seed) \0 key \0 name)        (scheme brume-sample-v1)
//   H = SHA-256; its first 8 bytes read big-endian as a 64-bit integer n;
//   u = (n >> 11) * 2^-53, a double in [0, 1) on the 53-bit grid,
//
// and the value is the distribution's inverse CDF at u:
//
//   uniform(a, b)      a + u (b - a)                       in [a, b)
//   loguniform(a, b)   exp(ln a + u (ln b - ln a)), a > 0  in [a, b)
//   choice(x, y, ...)  item floor(u n) of the n items      (each with probability 1/n)
//   a fixed value      that value (no draw)
//
// (a and b themselves bound the value; a value rounded just past b by the
// floating-point evaluation is held at b, which the up-front range check has
// already admitted). `name` is the parameter's canonical name (as in the
// record: "visibility", not an alias or "visibility_m"), so a parameter's
// value does not depend on how it was spelled, nor on which other parameters
// are sampled. Python reproduces a draw with
//   n = int.from_bytes(hashlib.sha256(b"brume-sample-v1\0" + str(seed).encode()
//         + b"\0" + key.encode() + b"\0" + name.encode()).digest()[:8], "big")
//   u = (n >> 11) / 2**53
// The scheme is recorded with every draw ({"sampler": "brume-sample-v1",
// "seed", "key", "specs"}); a different scheme gets a different name.
//
// Specs are checked before anything is drawn, against the effect's own
// ParamTable: the name must be declared (an unknown one names the nearest),
// the distribution must suit the parameter's kind (uniform/loguniform for
// real parameters; choice and fixed values for any), and every value it can
// produce must pass the table's range check — uniform(-1, 1) for albedo is an
// error, never clamped. The drawn set is then checked as a whole by the
// effect's validate_<effect> (a combination the run would ignore is refused).
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/error.hpp"
#include "brume/params.hpp"

namespace brume {

inline constexpr const char* kSamplerName = "brume-sample-v1";

// u in [0, 1) for (seed, key, name) by the scheme above.
double sample_unit(std::uint64_t seed, std::string_view key, std::string_view name);

// The first 8 bytes of SHA-256(msg), big-endian: the one hash the sampler
// and the batch's shards (brume/batch.hpp) are keyed by.
std::uint64_t sha256_prefix64(std::string_view msg);

// One parameter's distribution, parsed from what a user wrote.
struct Distribution {
  // seed: an integer parameter's per-key seed, floor(u·2^53) (the 53 bits of the key's hash): a
  // drop field, a noise pattern that no two frames share.
  enum class Kind { fixed, uniform, loguniform, choice, seed };
  Kind kind = Kind::fixed;
  double a = 0.0, b = 0.0;               // uniform, loguniform: the bounds
  std::vector<nlohmann::json> values;    // fixed: one value; choice: the items (parsed by the parameter's kind)
  std::string text() const;              // canonical text: "loguniform(50, 5000)", "choice(0.5, 0.9)", "0.9"
};

// Parses `text` for the parameter `spec`, whitespace tolerant: a fixed value
// (as the CLI flag takes it: "0.9", "auto", "naive", "0.8,0.8,0.9"),
// uniform(a, b), loguniform(a, b) with a > 0, choice(x, y, ...), seed()
// (a whole-number parameter only: values in [0, 2^53)). Every value
// the distribution can produce is range-checked by spec.check. Throws
// brume::Error naming the parameter, the text and what is allowed.
Distribution parse_distribution(const ParamSpec& spec, std::string_view text);

// The value of `d` at u in [0, 1) (the inverse CDF above).
nlohmann::json draw(const Distribution& d, double u);

// The effects whose parameters can be sampled: haze, fog, aerial, dof.
const std::vector<std::string>& sample_effects();

// The specs a draw uses: the effect's defaults, overridden and extended by
// `specs` (names may use '_' for '-', a trailing '_' as in Python's lambda_,
// and the flag's aliases; they are resolved to canonical names), each
// parsed and range-checked. A default
// that another given parameter excludes (haze: --visibility when --kappa-s is
// given) is dropped. Returns {canonical name: canonical spec text}.
std::map<std::string, std::string> resolve_sample_specs(std::string_view effect,
                                                        const std::map<std::string, std::string>& specs);

// The parameters for one frame: {name: value} with the record's names and
// JSON values (numbers, names, [r, g, b], null for "auto"), the dict the
// effect's params take. Checked as a whole by the effect's validate_<effect>.
nlohmann::json random_params(std::string_view effect, std::uint64_t seed, std::string_view key,
                             const std::map<std::string, std::string>& specs);

// Every set of values the specs can draw at the ends of their distributions:
// the product over the parameters of a fixed value, both bounds of a
// uniform or log-uniform range, each item of a choice (at most `max` sets;
// more is an Error naming the product's size). A check that holds at these
// corners holds for the ranges' monotone rules (a range, an order between two
// drawn values) wherever the draw falls: the transforms check them all when
// they are made. Each set as random_params returns one ({name: value}).
std::vector<nlohmann::json> sample_corners(std::string_view effect, const std::map<std::string, std::string>& specs,
                                           std::size_t max = 4096);

// How those values were drawn, for the record:
// {"sampler": "brume-sample-v1", "seed": S, "key": K, "specs": {name: text}}
// (the resolved specs, defaults included). S is written as a number.
nlohmann::json sample_provenance(std::string_view effect, std::uint64_t seed, std::string_view key,
                                 const std::map<std::string, std::string>& specs);

// Sets each {name: value} of `values` (random_params' dict) on `p` through
// the table: names resolved as above, each value type- and range-checked by
// its declaration. Returns the canonical names set (the `given` set of
// validate_<effect>). Throws brume::Error naming an undeclared parameter and
// the nearest declared one.
template <class P>
std::set<std::string> apply_params(const ParamTable<P>& table, P& p, const nlohmann::json& values);

// ---- implementation details used by the template ----------------------------------
namespace detail {
// The canonical name for `name` among `specs` ('_' -> '-', aliases); throws
// naming the nearest declared name when there is none.
std::string canonical_param_name(const std::vector<ParamSpec>& specs, std::string_view name, std::string_view where);
}  // namespace detail

template <class P>
std::set<std::string> apply_params(const ParamTable<P>& table, P& p, const nlohmann::json& values) {
  if (!values.is_object())
    throw Error("parameters for " + table.block() + " must be an object of {name: value}, got " + values.dump());
  std::vector<ParamSpec> specs;
  for (const Param<P>& d : table.params()) specs.push_back(d.spec);
  std::set<std::string> given;
  for (const auto& [name, v] : values.items()) {
    const std::string canon = detail::canonical_param_name(specs, name, table.block());
    const Param<P>& d = table.at(canon);
    d.spec.check(v);
    d.set(p, v);
    given.insert(canon);
  }
  return given;
}

}  // namespace brume
