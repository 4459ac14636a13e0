// brume — typed parameter declarations.
//
// Every parameter of every effect and shared block (diffusion, preparation,
// depth source, output, execution) is declared once, in a ParamTable: its
// user-facing name (the CLI flag without dashes, the record's key and later
// the Python keyword), type, unit, default (the struct's member initialiser),
// valid range or name table, and help. From that one declaration come
//   - the command-line flags and their help text (tools/brume/cli.hpp),
//   - every range check, with the flag's name in the message (validate),
//   - the JSON parameter record, re-runnable by `brume run record.json`
//     (to_json / from_json),
// so the four can never disagree (libvips' argument declarations; darktable's
// $MIN/$MAX/$DEFAULT).
//
// Types: real, integer, boolean, choice (an enum with one name table), RGB
// triple, text (file paths), each optionally "unset" (std::optional; the user
// writes `auto`, the record null) instead of a 0 sentinel; tables nest, so a
// block such as DiffusionParams is declared once and reused by every effect.
// Values travel as JSON: a number, an integer, a bool, a string, [r, g, b],
// or null for an unset optional.
#pragma once

#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/error.hpp"

namespace brume {

using Rgb = std::array<float, 3>;
using Pair = std::array<double, 2>;

// pair: two reals X,Y (a lens shift), each in the range.
enum class ParamKind { real, integer, boolean, choice, rgb, text, pair };

// Allowed interval of a real or integer parameter (and of each RGB component).
struct Range {
  double min = -INFINITY, max = INFINITY;
  bool min_open = false, max_open = false;
  static Range any() { return {}; }
  static Range at_least(double lo) { return {lo, INFINITY, false, false}; }
  static Range above(double lo) { return {lo, INFINITY, true, false}; }
  static Range closed(double lo, double hi) { return {lo, hi, false, false}; }
  static Range left_open(double lo, double hi) { return {lo, hi, true, false}; }
  bool contains(double v) const;
  std::string text() const;  // "[0, inf)", "(0, 0.25]"
};

// One parameter, independent of the struct that holds it.
struct ParamSpec {
  std::string name;                  // flag name without dashes; record key; Python keyword
  std::vector<std::string> aliases;  // other accepted flag names (e.g. fog-color for airlight)
  ParamKind kind = ParamKind::real;
  std::string unit;                  // "m", "px", "1" (dimensionless); empty for text/choice/boolean
  std::string help;
  Range range;                       // real, integer, rgb components
  std::vector<std::string> choices;  // choice: the names, in declaration order
  bool optional = false;             // may be unset (no 0 sentinels)
  std::string unset_word = "auto";   // what the user writes for "unset"
  std::vector<std::string> words;    // rgb, real: names accepted instead of the value, stored as the name
                                     // (aerial's --airlight horizon: a rule that estimates the colour;
                                     // --turbidity contrast: a rule that fits the value on the image)
  std::string block;                 // the declaring block: "haze", "diffusion", "prepare", ...
  bool allow_inf = false;            // real: +inf is a meaningful value (an infinite far plane)
  bool output_file = false;          // text: names a file (depth prepare's --masks: a directory) the run
                                     // writes; brume run moves it under --out-dir, brume batch names its
                                     // own outputs after the frame's key
  std::string output_of;             // output_file written only when the parameter named here (an input
  std::string output_ext;            // file) is given; brume batch names it <key stem><output_ext> beside
                                     // the frame's image (a camera effect's --lidar-out of --lidar: ".bin")
  bool input_file = false;           // text: names a file the run reads (reads_file): its record holds the file's
                                     // SHA-256, which brume run checks, and refuses a record without it
  std::string input_file_none;       // a value of an input_file that names no file ("default" sensitivities)
  char input_file_cut = 0;           // the file is the value up to this character ('#': DATABASE.txt#CAMERA)
  std::string input_file_prefix;     // a value names a file only after this prefix (--image-transfer's
                                     // "table:" of table:FILE); values without it name none
  int input_hashed_since = 0;        // records of this schema on hold its hash (calibrations 4; --like,
                                     // --view-matrix, --turbidity-from 5: schema 4 was written without)
  int since_schema = 0;              // the record schema that introduced it (0: always there); a job that
  nlohmann::json before_schema;      // lacks it ran as this value says (brume run sets it; record_job)
  // Where records of earlier schemas kept it ("block.name": depth of
  // field's "dof.focal-length" before the lens joined the depth block):
  // from_json reads a value found there as this parameter's.
  std::vector<std::string> formerly;

  // Help with unit, range or choices, for --help and docs.
  std::string describe() const;
  // Text a user would type for this value (for defaults in --help).
  std::string format(const nlohmann::json& v) const;
  // Parse what a user typed (CLI) into a value; throws Error naming --name.
  nlohmann::json parse(const std::string& text) const;
  // Check a value's type and range; throws Error naming --name, the value,
  // what is allowed and the fix.
  void check(const nlohmann::json& v) const;
};

template <class E>
using EnumNames = std::vector<std::pair<E, const char*>>;

// Name <-> value through one name table; parse errors list the names.
template <class E>
std::string enum_name(const EnumNames<E>& names, E v) {
  for (const auto& [e, n] : names)
    if (e == v) return n;
  return "?";
}
template <class E>
E parse_enum(const EnumNames<E>& names, const std::string& s, const std::string& flag) {
  for (const auto& [e, n] : names)
    if (s == n) return e;
  std::string all;
  for (const auto& [e, n] : names) all += (all.empty() ? "" : ", ") + std::string(n);
  throw Error(flag + " '" + s + "' is not allowed; use one of: " + all);
}

template <class P>
struct Param {
  ParamSpec spec;
  std::function<nlohmann::json(const P&)> get;
  std::function<void(P&, const nlohmann::json&)> set;  // the value has passed spec.check
};

// Text that brume keeps in a record or a manifest (a path, a frame key, an
// argument) must be UTF-8: JSON holds Unicode text only, and a record that
// replaced the bytes of a file name with U+FFFD could not be run again.
// first_invalid_utf8 is the offset of the first byte that does not begin a
// well-formed sequence (RFC 3629: no overlong forms, no surrogates, nothing
// above U+10FFFF), npos when there is none; check_utf8 throws an Error that
// names `what`, shows the value with its bad bytes as \xHH, and says how to
// fix it.
std::size_t first_invalid_utf8(const std::string& text);
void check_utf8(const std::string& text, const std::string& what);

// `text` with every mention "--NAME" of a flag for which is_flag(NAME) holds
// rewritten "--PREFIXNAME": a nested block's help and error messages name the
// flags as the user of the enclosing command types them (--dof-focal-length).
std::string prefix_flag_mentions(const std::string& text, const std::string& prefix,
                                 const std::function<bool(const std::string&)>& is_flag);

template <class P>
class ParamTable {
 public:
  explicit ParamTable(std::string block) : block_(std::move(block)) {}
  const std::string& block() const { return block_; }
  const std::vector<Param<P>>& params() const { return params_; }

  ParamTable& real(const char* name, double P::*m, const char* unit, Range r, const char* help) {
    return add(spec(name, ParamKind::real, unit, help, r),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<double>(); });
  }
  ParamTable& real(const char* name, std::optional<double> P::*m, const char* unit, Range r, const char* help,
                   const char* unset_word = "auto") {
    ParamSpec s = spec(name, ParamKind::real, unit, help, r);
    s.optional = true;
    s.unset_word = unset_word;
    return add(std::move(s), [m](const P& p) { return (p.*m) ? nlohmann::json(*(p.*m)) : nlohmann::json(); },
               [m](P& p, const nlohmann::json& v) {
                 if (v.is_null()) p.*m = std::nullopt; else p.*m = v.get<double>();
               });
  }
  // A struct field that stores "unset" as a sentinel (NaN, or 0 where 0 is not
  // a valid value) for API compatibility; users and records see unset.
  ParamTable& real_or_unset(const char* name, double P::*m, const char* unit, Range r, const char* help,
                            double sentinel, const char* unset_word = "auto") {
    ParamSpec s = spec(name, ParamKind::real, unit, help, r);
    s.optional = true;
    s.unset_word = unset_word;
    const bool nan = std::isnan(sentinel);
    return add(std::move(s),
               [m, sentinel, nan](const P& p) {
                 const double v = p.*m;
                 return (nan ? std::isnan(v) : v == sentinel) ? nlohmann::json() : nlohmann::json(v);
               },
               [m, sentinel](P& p, const nlohmann::json& v) { p.*m = v.is_null() ? sentinel : v.get<double>(); });
  }
  // A real_or_unset that may instead be one of `words` (a named rule that
  // finds the value): the number in a nested struct (`outer`.*m), the word
  // beside it in P ("" when the value is a number or unset; the number is
  // then the sentinel).
  template <class Q>
  ParamTable& real_or_word(const char* name, Q P::*outer, double Q::*m, std::string P::*word,
                           std::vector<std::string> words, const char* unit, Range r, const char* help,
                           double sentinel, const char* unset_word = "auto") {
    ParamSpec s = spec(name, ParamKind::real, unit, help, r);
    s.optional = true;
    s.unset_word = unset_word;
    s.words = std::move(words);
    const bool nan = std::isnan(sentinel);
    return add(std::move(s),
               [outer, m, word, sentinel, nan](const P& p) {
                 if (!(p.*word).empty()) return nlohmann::json(p.*word);
                 const double v = (p.*outer).*m;
                 return (nan ? std::isnan(v) : v == sentinel) ? nlohmann::json() : nlohmann::json(v);
               },
               [outer, m, word, sentinel](P& p, const nlohmann::json& v) {
                 p.*word = v.is_string() ? v.get<std::string>() : std::string();
                 (p.*outer).*m = v.is_number() ? v.get<double>() : sentinel;
               });
  }
  ParamTable& integer(const char* name, int P::*m, const char* unit, Range r, const char* help) {
    return add(spec(name, ParamKind::integer, unit, help, r),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<int>(); });
  }
  template <class I>
  ParamTable& count(const char* name, I P::*m, const char* unit, Range r, const char* help) {
    return add(spec(name, ParamKind::integer, unit, help, r),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<I>(); });
  }
  ParamTable& boolean(const char* name, bool P::*m, const char* help) {
    return add(spec(name, ParamKind::boolean, "", help, {}),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<bool>(); });
  }
  template <class E>
  ParamTable& choice(const char* name, E P::*m, const EnumNames<E>& names, const char* help) {
    ParamSpec s = spec(name, ParamKind::choice, "", help, {});
    for (const auto& [e, n] : names) s.choices.emplace_back(n);
    return add(std::move(s), [m, names](const P& p) { return nlohmann::json(enum_name(names, p.*m)); },
               [m, names, flag = std::string("--") + name](P& p, const nlohmann::json& v) {
                 p.*m = parse_enum(names, v.get<std::string>(), flag);
               });
  }
  // A choice stored as its name (a struct field that is a string).
  ParamTable& choice(const char* name, std::string P::*m, const std::vector<const char*>& names, const char* help) {
    ParamSpec s = spec(name, ParamKind::choice, "", help, {});
    for (const char* n : names) s.choices.emplace_back(n);
    return add(std::move(s), [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<std::string>(); });
  }
  ParamTable& rgb(const char* name, std::optional<Rgb> P::*m, const char* unit, Range r, const char* help,
                  const char* unset_word = "auto") {
    ParamSpec s = spec(name, ParamKind::rgb, unit, help, r);
    s.optional = true;
    s.unset_word = unset_word;
    return add(std::move(s), [m](const P& p) { return (p.*m) ? nlohmann::json(*(p.*m)) : nlohmann::json(); },
               [m](P& p, const nlohmann::json& v) {
                 if (v.is_null()) p.*m = std::nullopt; else p.*m = v.get<Rgb>();
               });
  }
  // An rgb that may instead be one of `words` (a named rule for the colour),
  // kept in `word` ("" when the value is a colour or unset).
  ParamTable& rgb_or_word(const char* name, std::optional<Rgb> P::*m, std::string P::*word,
                          std::vector<std::string> words, const char* unit, Range r, const char* help,
                          const char* unset_word = "auto") {
    ParamSpec s = spec(name, ParamKind::rgb, unit, help, r);
    s.optional = true;
    s.unset_word = unset_word;
    s.words = std::move(words);
    return add(std::move(s),
               [m, word](const P& p) {
                 if (!(p.*word).empty()) return nlohmann::json(p.*word);
                 return (p.*m) ? nlohmann::json(*(p.*m)) : nlohmann::json();
               },
               [m, word](P& p, const nlohmann::json& v) {
                 p.*word = v.is_string() ? v.get<std::string>() : std::string();
                 if (v.is_null() || v.is_string()) p.*m = std::nullopt; else p.*m = v.get<Rgb>();
               });
  }
  ParamTable& pair(const char* name, Pair P::*m, const char* unit, Range r, const char* help) {
    return add(spec(name, ParamKind::pair, unit, help, r),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<Pair>(); });
  }
  ParamTable& text(const char* name, std::string P::*m, const char* help) {
    return add(spec(name, ParamKind::text, "", help, {}),
               [m](const P& p) { return nlohmann::json(p.*m); },
               [m](P& p, const nlohmann::json& v) { p.*m = v.get<std::string>(); });
  }
  // Any other mapping between a value and P (the spec's block is set here).
  ParamTable& custom(ParamSpec s, std::function<nlohmann::json(const P&)> g,
                     std::function<void(P&, const nlohmann::json&)> st) {
    s.block = block_;
    return add(std::move(s), std::move(g), std::move(st));
  }
  // +inf is allowed for the last declared parameter.
  ParamTable& infinite() {
    params_.back().spec.allow_inf = true;
    return *this;
  }
  // The last declared (text) parameter names a file the run writes.
  ParamTable& writes_file() {
    params_.back().spec.output_file = true;
    return *this;
  }
  // The last declared (text) parameter names a file the run reads: its
  // record must hold the file's {path, sha256}, or brume run refuses it
  // (issue #51). `none`: a value that names no file; `cut`: the file is the
  // value up to that character.
  // `hashed_since`: the record schema from which every record holds the
  // file's hash (0: all of them); an older record without it runs on the file
  // as it is now, with a warning.
  ParamTable& reads_file(const char* none = "", char cut = 0, int hashed_since = 0) {
    params_.back().spec.input_file = true;
    params_.back().spec.input_file_none = none;
    params_.back().spec.input_file_cut = cut;
    params_.back().spec.input_hashed_since = hashed_since;
    return *this;
  }
  // The same for an output that exists only with the input `of` (brume
  // batch names it after the frame's key with the extension `ext`).
  ParamTable& writes_file_of(const char* of, const char* ext) {
    params_.back().spec.output_file = true;
    params_.back().spec.output_of = of;
    params_.back().spec.output_ext = ext;
    return *this;
  }
  // The last declared parameter came with record schema `version` and a new
  // rule; `older` is its value that gives the rule of the records before.
  ParamTable& since(int version, nlohmann::json older) {
    params_.back().spec.since_schema = version;
    params_.back().spec.before_schema = std::move(older);
    return *this;
  }
  // Records of earlier schemas kept the last declared parameter as
  // "block.name" (ParamSpec::formerly).
  ParamTable& formerly(const char* block_dot_name) {
    params_.back().spec.formerly.emplace_back(block_dot_name);
    return *this;
  }
  // Other accepted flag names for the last declared parameter.
  ParamTable& alias(const char* a) {
    params_.back().spec.aliases.emplace_back(a);
    return *this;
  }
  // Every parameter of a nested block (declared once, reused by every effect).
  template <class Q>
  ParamTable& nest(Q P::*m, const ParamTable<Q>& sub) {
    for (const Param<Q>& q : sub.params()) {
      if (find(q.spec.name)) throw Error("internal: parameter '" + q.spec.name + "' declared twice in " + block_);
      params_.push_back({q.spec, [m, g = q.get](const P& p) { return g(p.*m); },
                         [m, s = q.set](P& p, const nlohmann::json& v) { s(p.*m, v); }});
    }
    return *this;
  }

  // Every parameter of another table of the same struct, as declared there
  // (a table that adds to another: depth of field's sampling adds the lens).
  ParamTable& extend(const ParamTable<P>& other) {
    for (const Param<P>& q : other.params()) {
      if (find(q.spec.name)) throw Error("internal: parameter '" + q.spec.name + "' declared twice in " + block_);
      params_.push_back(q);
    }
    return *this;
  }

  // Every parameter of a base class's table, as declared there (P derives
  // from Q: a struct that extends a shared block, as layered fog's parameters
  // extend the height profile's), less `skip`.
  template <class Q>
  ParamTable& extend_base(const ParamTable<Q>& base, const std::set<std::string>& skip = {}) {
    static_assert(std::is_base_of_v<Q, P>, "extend_base: P must derive from Q");
    for (const Param<Q>& q : base.params()) {
      if (skip.count(q.spec.name)) continue;
      if (find(q.spec.name)) throw Error("internal: parameter '" + q.spec.name + "' declared twice in " + block_);
      params_.push_back({q.spec, [g = q.get](const P& p) { return g(p); },
                         [s = q.set](P& p, const nlohmann::json& v) { s(p, v); }});
    }
    return *this;
  }

  // A nested block without some of its parameters, where the effect declares
  // its own parameter of that name (depth of field's --scheme, whose choices
  // go beyond the diffusion engine's and set the engine's scheme).
  template <class Q>
  ParamTable& nest_except(Q P::*m, const ParamTable<Q>& sub, const std::set<std::string>& skip) {
    for (const Param<Q>& q : sub.params()) {
      if (skip.count(q.spec.name)) continue;
      if (find(q.spec.name)) throw Error("internal: parameter '" + q.spec.name + "' declared twice in " + block_);
      params_.push_back({q.spec, [m, g = q.get](const P& p) { return g(p.*m); },
                         [m, s = q.set](P& p, const nlohmann::json& v) { s(p.*m, v); }});
    }
    return *this;
  }

  // The same with every flag name prefixed ("sky-": --sky-projection), for a
  // block that appears twice in one command (the photo's and the sky's), or
  // whose names would collide with the effect's (a camera effect's LiDAR:
  // --lidar-seed); `skip`: names (unprefixed) left out.
  template <class Q>
  ParamTable& nest(Q P::*m, const ParamTable<Q>& sub, const std::string& prefix,
                   const std::set<std::string>& skip = {}) {
    return nest_prefixed(sub, prefix, skip, [m](const Param<Q>& q) {
      return Param<P>{{},
                      [m, g = q.get](const P& p) { return g(p.*m); },
                      [m, s = q.set](P& p, const nlohmann::json& v) { s(p.*m, v); }};
    });
  }
  // The same for a block that the struct holds as the sub-table's JSON
  // ({"name": value}, unprefixed names; a name not there has Q's default),
  // so that the struct's header need not name Q: a camera effect's scan
  // medium settings (brume/lidar_camera.hpp). Each value is stored as Q's
  // field writes it back, so the records equal a typed block's.
  template <class Q>
  ParamTable& nest_json(nlohmann::json P::*m, const ParamTable<Q>& sub, const std::string& prefix,
                        const std::set<std::string>& skip = {}) {
    return nest_prefixed(sub, prefix, skip, [m](const Param<Q>& q) {
      return Param<P>{{},
                      [m, n = q.spec.name, g = q.get](const P& p) {
                        const auto it = (p.*m).find(n);
                        return it != (p.*m).end() ? *it : g(Q{});
                      },
                      [m, n = q.spec.name, g = q.get, s = q.set](P& p, const nlohmann::json& v) {
                        Q typed;
                        s(typed, v);
                        (p.*m)[n] = g(typed);
                      }};
    });
  }

  // Whether NAME is one of this table's flags or their aliases.
  bool declares(const std::string& name) const {
    for (const auto& p : params_) {
      if (p.spec.name == name) return true;
      for (const auto& a : p.spec.aliases)
        if (a == name) return true;
    }
    return false;
  }

  // The parameter an earlier schema's record kept as "block.name", or null.
  const Param<P>* former(const std::string& key) const {
    for (const auto& p : params_)
      for (const auto& f : p.spec.formerly)
        if (f == key) return &p;
    return nullptr;
  }

  const Param<P>* find(const std::string& name) const {
    for (const auto& p : params_)
      if (p.spec.name == name) return &p;
    return nullptr;
  }
  const Param<P>& at(const std::string& name) const {
    const Param<P>* p = find(name);
    if (!p) throw Error("internal: parameter '" + name + "' is not declared in block " + block_);
    return *p;
  }

  // Range- and type-check every parameter's current value.
  void validate(const P& p) const {
    for (const auto& d : params_) d.spec.check(d.get(p));
  }
  // Set one parameter from what a user typed, checked.
  void set_text(P& p, const std::string& name, const std::string& text) const {
    const Param<P>& d = at(name);
    const nlohmann::json v = d.spec.parse(text);
    d.spec.check(v);
    d.set(p, v);
  }
  // True when `name` was given explicitly or differs from its default: a
  // value the run would ignore must be refused, not dropped.
  bool is_set(const P& p, const std::string& name, const std::set<std::string>& given) const {
    return given.count(name) > 0 || at(name).get(p) != at(name).get(P{});
  }
  // {"block": {"name": value, ...}, ...}: nested blocks keep their own key.
  nlohmann::json to_json(const P& p) const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& d : params_) j[d.spec.block][d.spec.name] = d.get(p);
    return j;
  }
  // {"block": {"name": unit}} for the record.
  nlohmann::json units() const {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& d : params_)
      if (!d.spec.unit.empty()) j[d.spec.block][d.spec.name] = d.spec.unit;
    return j;
  }
  // Inverse of to_json: every key must be declared; absent keys keep their
  // value; every value is checked. `where` names the source in messages.
  std::set<std::string> from_json(P& p, const nlohmann::json& j, const std::string& where) const {
    std::set<std::string> given;
    if (!j.is_object()) throw Error(where + ": expected an object of parameter blocks");
    for (const auto& [block, vals] : j.items()) {
      if (!vals.is_object()) throw Error(where + ": block '" + block + "' is not an object");
      for (const auto& [name, v] : vals.items()) {
        const Param<P>* d = find(name);
        if (!d || d->spec.block != block) d = former(block + "." + name);
        if (!d)
          throw Error(where + ": '" + block + "." + name + "' is not a parameter of this command");
        if (given.count(d->spec.name) && d->spec.block != block) continue;  // the current key wins over a former one
        d->spec.check(v);
        d->set(p, v);
        given.insert(name);
      }
    }
    return given;
  }

 private:
  // The prefixed nests: each of sub's parameters (less `skip`) renamed
  // "PREFIXNAME" in block PREFIX (less its '-'), reached through `access`.
  template <class Q, class Access>
  ParamTable& nest_prefixed(const ParamTable<Q>& sub, const std::string& prefix, const std::set<std::string>& skip,
                            const Access& access) {
    for (const Param<Q>& q : sub.params()) {
      if (skip.count(q.spec.name)) continue;
      ParamSpec sp = q.spec;
      sp.name = prefix + sp.name;
      for (std::string& a : sp.aliases) a = prefix + a;
      // One block for the prefixed flags in records and --help ("sky-" -> "sky").
      sp.block = prefix.size() > 1 && prefix.back() == '-' ? prefix.substr(0, prefix.size() - 1) : prefix;
      sp.help = prefix_flag_mentions(sp.help, prefix,
                                     [&sub, &skip](const std::string& n) { return sub.declares(n) && !skip.count(n); });
      if (find(sp.name)) throw Error("internal: parameter '" + sp.name + "' declared twice in " + block_);
      Param<P> d = access(q);
      d.spec = std::move(sp);
      params_.push_back(std::move(d));
    }
    return *this;
  }
  ParamSpec spec(const char* name, ParamKind k, const char* unit, const char* help, Range r) const {
    ParamSpec s;
    s.name = name;
    s.kind = k;
    s.unit = unit;
    s.help = help;
    s.range = r;
    s.block = block_;
    return s;
  }
  ParamTable& add(ParamSpec s, std::function<nlohmann::json(const P&)> g,
                  std::function<void(P&, const nlohmann::json&)> st) {
    for (const auto& d : params_)
      if (d.spec.name == s.name) throw Error("internal: parameter '" + s.name + "' declared twice in " + block_);
    params_.push_back({std::move(s), std::move(g), std::move(st)});
    return *this;
  }
  std::string block_;
  std::vector<Param<P>> params_;
};

}  // namespace brume
