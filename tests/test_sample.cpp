// The parameter sampler (brume/sample.hpp): draws keyed by (seed, key, name)
// and pinned by an independent SHA-256, their distributions (KS, chi-square),
// bounds, the up-front checks and `brume sample`.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "brume/dof.hpp"
#include "brume/haze.hpp"
#include "brume/rain.hpp"
#include "brume/sample.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

// Kolmogorov-Smirnov statistic D = sup |F_n(x) - x| of samples against U(0, 1).
double ks_uniform(std::vector<double> u) {
  std::sort(u.begin(), u.end());
  const double n = static_cast<double>(u.size());
  double d = 0;
  for (std::size_t i = 0; i < u.size(); ++i)
    d = std::max({d, (i + 1) / n - u[i], u[i] - i / n});
  return d;
}

// The asymptotic KS critical value at significance 0.001: K = 1.9495 (the
// Kolmogorov distribution's 0.999 quantile), D_crit = K / sqrt(n); for
// n = 10 000, 0.0195. The draws are deterministic, so each KS test below
// either always passes or always fails; a correct sampler fails it with
// probability 0.001 over the choice of the pinned scheme and seed.
constexpr double kKs999 = 1.9495;

std::string key_of(int i) { return "frame/" + std::to_string(i) + ".png"; }

}  // namespace

// The scheme pinned by an independent implementation (Python's hashlib), so
// that it cannot drift:
//   python3 -c "import hashlib; n=int.from_bytes(hashlib.sha256(b'brume-sample-v1\0'+str(7).encode()
//     +b'\0'+b'Art/view1.png'+b'\0'+b'visibility').digest()[:8],'big'); print(hex(n), repr((n>>11)/2**53))"
//   -> 0x3cc3132a503d5c9e 0.23735160620730278
// (seed 0, key "", "albedo": 0x31e0d673683ce23b 0.19483700101430967; seed 2^64-1, "key#3", "lambda":
// 0x4b8374e16ab649c8 0.2949746179899303). u is k 2^-53 exactly, so equality is exact.
TEST(Sample, HashGoldenValues) {
  EXPECT_EQ(sample_unit(7, "Art/view1.png", "visibility"), 0.23735160620730278);
  EXPECT_EQ(sample_unit(0, "", "albedo"), 0.19483700101430967);
  EXPECT_EQ(sample_unit(18446744073709551615ull, "key#3", "lambda"), 0.2949746179899303);
}

// The values of haze's defaults for that frame, as Python computes them:
//   visibility exp(log 50 + u (log 5000 - log 50)) = 149.16715845261467,
//   albedo 0.8 + u (1 - 0.8) = 0.9648168283635619, lambda 8 u = 6.2468525796096.
// albedo and lambda are the same IEEE operations in both (exact); the
// visibility goes through libm's exp/log (faithful to 1 ulp each): 1e-13 relative.
TEST(Sample, HazeDefaultsGolden) {
  const nlohmann::json v = random_params("haze", 7, "Art/view1.png", {});
  ASSERT_EQ(v.size(), 3u) << v.dump();
  EXPECT_NEAR(v["visibility"].get<double>(), 149.16715845261467, 149.2 * 1e-13);
  EXPECT_EQ(v["albedo"].get<double>(), 0.9648168283635619);
  EXPECT_EQ(v["lambda"].get<double>(), 6.2468525796096);
}

// A parameter's value depends on (seed, key, its name) only: not on the other
// parameters sampled, their order or count, nor on how the name was spelt.
TEST(Sample, KeyedByNameNotByOrderOrSet) {
  const std::map<std::string, std::string> alone = {{"visibility", "loguniform(100, 2000)"}};
  const std::map<std::string, std::string> more = {{"visibility", "loguniform(100, 2000)"},
                                                    {"lambda", "uniform(1, 2)"},
                                                    {"albedo", "choice(0.9, 1)"},
                                                    {"composite", "choice(premultiplied, naive)"}};
  for (int i = 0; i < 50; ++i) {
    const nlohmann::json a = random_params("haze", 11, key_of(i), alone);
    const nlohmann::json b = random_params("haze", 11, key_of(i), more);
    EXPECT_EQ(a["visibility"], b["visibility"]) << key_of(i);
    // The same value as one independent draw of that name.
    const Distribution d = parse_distribution(haze_param_table().at("visibility").spec, "loguniform(100, 2000)");
    EXPECT_EQ(a["visibility"], draw(d, sample_unit(11, key_of(i), "visibility")));
  }
  // '_' for '-' draws the same (the canonical name is hashed).
  const nlohmann::json dash = random_params("haze", 3, "k", {{"kappa-s", "uniform(0.1, 1)"}});
  const nlohmann::json under = random_params("haze", 3, "k", {{"kappa_s", "uniform(0.1, 1)"}});
  EXPECT_EQ(dash, under);
  // Python's escape of the keyword: lambda_ is lambda.
  EXPECT_EQ(random_params("haze", 3, "k", {{"lambda_", "uniform(1, 2)"}}),
            random_params("haze", 3, "k", {{"lambda", "uniform(1, 2)"}}));
}

TEST(Sample, DifferentKeysAndSeedsDiffer) {
  std::set<double> seen;
  for (int i = 0; i < 2000; ++i) seen.insert(random_params("haze", 7, key_of(i), {})["visibility"].get<double>());
  EXPECT_EQ(seen.size(), 2000u);  // 53-bit draws: a collision among 2000 has probability ~ 2e-10
  int same = 0;
  for (int i = 0; i < 200; ++i)
    same += random_params("haze", 7, key_of(i), {}) == random_params("haze", 8, key_of(i), {});
  EXPECT_EQ(same, 0);
  // Names are separate streams: albedo's u is not visibility's.
  EXPECT_NE(sample_unit(7, "k", "albedo"), sample_unit(7, "k", "visibility"));
}

// uniform(0, 8) and loguniform(50, 5000) over 10 000 keys against their CDFs.
TEST(Sample, KolmogorovSmirnov) {
  const int n = 10000;
  const double crit = kKs999 / std::sqrt(n);  // 0.0195
  for (std::uint64_t seed : {7ull, 2026ull}) {
    std::vector<double> lam, vis;
    for (int i = 0; i < n; ++i) {
      const nlohmann::json v = random_params("haze", seed, key_of(i), {});
      lam.push_back(v["lambda"].get<double>() / 8.0);
      vis.push_back((std::log(v["visibility"].get<double>()) - std::log(50.0)) / (std::log(5000.0) - std::log(50.0)));
    }
    EXPECT_LT(ks_uniform(lam), crit) << "seed " << seed;
    EXPECT_LT(ks_uniform(vis), crit) << "seed " << seed;
    // The test can fail: the same statistic rejects a visibility drawn uniformly (not log-uniformly).
    std::vector<double> wrong;
    for (double x : vis) wrong.push_back((std::exp(std::log(50.0) + x * std::log(100.0)) - 50.0) / 4950.0);
    EXPECT_GT(ks_uniform(wrong), crit);
  }
}

// choice(1.4, 2, 2.8, 4, 5.6, 8) over 10 000 keys: chi-square with 5 degrees
// of freedom against equal frequencies; critical value at 0.001: 20.515 (a
// correct sampler fails with probability 0.001 over the choice of scheme/seed).
TEST(Sample, ChoiceChiSquare) {
  const int n = 10000;
  std::map<double, int> count;
  for (int i = 0; i < n; ++i) ++count[random_params("dof", 5, key_of(i), {})["f-number"].get<double>()];
  ASSERT_EQ(count.size(), 6u);
  double chi2 = 0;
  for (const auto& [stop, c] : count) {
    const double e = n / 6.0;
    chi2 += (c - e) * (c - e) / e;
  }
  EXPECT_LT(chi2, 20.515);
  EXPECT_EQ(count.begin()->first, 1.4);
  EXPECT_EQ(count.rbegin()->first, 8.0);
}

TEST(Sample, BoundsRespected) {
  const ParamSpec& albedo = haze_param_table().at("albedo").spec;
  const ParamSpec& vis = haze_param_table().at("visibility").spec;
  const Distribution u = parse_distribution(albedo, "uniform(0.8, 1)");
  const Distribution l = parse_distribution(vis, "loguniform(50, 5000)");
  const double below1 = 1.0 - 0x1p-53;  // the largest u
  EXPECT_EQ(draw(u, 0.0).get<double>(), 0.8);
  EXPECT_LE(draw(u, below1).get<double>(), 1.0);
  EXPECT_EQ(draw(l, 0.0).get<double>(), 50.0);  // exp(log 50) is held to a
  EXPECT_LE(draw(l, below1).get<double>(), 5000.0);
  EXPECT_GE(draw(l, 0.0).get<double>(), 50.0);
  // A narrow range where rounding matters: 0.1 + u (0.3 - 0.1) never leaves [0.1, 0.3].
  const Distribution narrow = parse_distribution(albedo, "uniform(0.1, 0.3)");
  for (double x : {0.0, 0.5, below1, 1.0 - 0x1p-52}) {
    const double v = draw(narrow, x).get<double>();
    EXPECT_GE(v, 0.1);
    EXPECT_LE(v, 0.3);
  }
  for (int i = 0; i < 10000; ++i) {
    const nlohmann::json v = random_params("haze", 9, key_of(i), {});
    ASSERT_GE(v["visibility"].get<double>(), 50.0);
    ASSERT_LE(v["visibility"].get<double>(), 5000.0);
    ASSERT_GE(v["albedo"].get<double>(), 0.8);
    ASSERT_LE(v["albedo"].get<double>(), 1.0);
    ASSERT_GE(v["lambda"].get<double>(), 0.0);
    ASSERT_LE(v["lambda"].get<double>(), 8.0);
  }
}

// Every effect's defaults give usable parameter sets (validate_<effect> passes on each draw).
TEST(Sample, EveryEffectsDefaultsValidate) {
  for (const std::string& e : sample_effects())
    for (int i = 0; i < 300; ++i) EXPECT_NO_THROW(random_params(e, 1, key_of(i), {})) << e << " " << key_of(i);
  // The sampled effects are the commands that declare a sampling block, in
  // the list's order; the camera effects and the scan's fog among them.
  std::vector<std::string> declared;
  for (const CommandDef& c : commands())
    if (c.sampling) declared.push_back(c.name);
  EXPECT_EQ(sample_effects(), declared);
  for (const char* e : {"haze", "aerial", "fog", "dof", "lidar fog"})
    EXPECT_NE(std::find(declared.begin(), declared.end(), e), declared.end()) << e << " lost its sampling block";
}

TEST(Sample, SpecsParseWhitespaceAndKinds) {
  const ParamSpec& vis = haze_param_table().at("visibility").spec;
  EXPECT_EQ(parse_distribution(vis, "  loguniform ( 100 ,2000 ) ").text(), "loguniform(100, 2000)");
  EXPECT_EQ(parse_distribution(vis, "Uniform(1,2)").text(), "uniform(1, 2)");
  EXPECT_EQ(parse_distribution(vis, " 800 ").text(), "800");
  EXPECT_EQ(parse_distribution(vis, "auto").values.at(0), nullptr);  // fixed: unset
  EXPECT_EQ(parse_distribution(vis, "choice(100, 1e3)").text(), "choice(100, 1000)");
  const ParamSpec& comp = haze_param_table().at("composite").spec;
  const Distribution c = parse_distribution(comp, "choice( premultiplied , naive )");
  ASSERT_EQ(c.values.size(), 2u);
  EXPECT_EQ(draw(c, 0.49), "premultiplied");
  EXPECT_EQ(draw(c, 0.5), "naive");
  EXPECT_EQ(parse_distribution(haze_param_table().at("airlight").spec, "0.8, 0.8,0.9").values.at(0),
            nlohmann::json({0.8f, 0.8f, 0.9f}));
}

TEST(Sample, BadSpecsGiveClearErrors) {
  const ParamSpec& albedo = haze_param_table().at("albedo").spec;
  const ParamSpec& vis = haze_param_table().at("visibility").spec;
  auto err = [](const ParamSpec& s, const std::string& t) { return error_of([&] { parse_distribution(s, t); }); };
  std::string m = err(albedo, "uniform(-1, 1)");  // can leave [0, 1]: refused up front, not clamped
  EXPECT_NE(m.find("--albedo"), std::string::npos) << m;
  EXPECT_NE(m.find("uniform(-1, 1)"), std::string::npos) << m;
  EXPECT_NE(m.find("[0, 1]"), std::string::npos) << m;
  m = err(albedo, "uniform(0.5, 1.5)");
  EXPECT_NE(m.find("upper bound 1.5"), std::string::npos) << m;
  m = err(albedo, "2");  // a constant: the declaration's message, said once
  EXPECT_EQ(m, "sampling --albedo '2': " + error_of([&] { albedo.check(2.0); })) << m;
  m = err(vis, "loguniform(0, 10)");
  EXPECT_NE(m.find("0 < a"), std::string::npos) << m;
  m = err(vis, "uniform(0, 10)");  // visibility > 0: the lower bound 0 is not a visibility
  EXPECT_NE(m.find("lower bound 0"), std::string::npos) << m;
  m = err(vis, "uniform(5, 1)");
  EXPECT_NE(m.find("a < b"), std::string::npos) << m;
  m = err(vis, "uniform(1, 1)");
  EXPECT_NE(m.find("a < b"), std::string::npos) << m;
  m = err(vis, "normal(100, 10)");
  EXPECT_NE(m.find("'normal' is not a distribution"), std::string::npos) << m;
  EXPECT_NE(m.find("loguniform(a, b)"), std::string::npos) << m;  // says what is allowed
  m = err(vis, "uniform(1)");
  EXPECT_NE(m.find("two bounds"), std::string::npos) << m;
  m = err(vis, "uniform(1, 2");
  EXPECT_NE(m.find("')'"), std::string::npos) << m;
  m = err(vis, "uniform(1, x)");
  EXPECT_NE(m.find("'x' is not a finite number"), std::string::npos) << m;
  m = err(vis, "uniform(1, inf)");
  EXPECT_NE(m.find("'inf' is not a finite number"), std::string::npos) << m;
  m = err(vis, "choice()");
  EXPECT_NE(m.find("at least one item"), std::string::npos) << m;
  m = err(vis, "choice(100, , 200)");
  EXPECT_NE(m.find("empty"), std::string::npos) << m;
  m = err(vis, "fog");
  EXPECT_NE(m.find("not a number"), std::string::npos) << m;
  m = err(vis, "");
  EXPECT_NE(m.find("empty"), std::string::npos) << m;
  m = err(haze_param_table().at("composite").spec, "choice(premultiplied, bogus)");
  EXPECT_NE(m.find("bogus"), std::string::npos) << m;
  EXPECT_NE(m.find("use one of: premultiplied, naive"), std::string::npos) << m;
  m = err(haze_param_table().at("composite").spec, "uniform(0, 1)");
  EXPECT_NE(m.find("--composite is a name"), std::string::npos) << m;
  m = err(haze_param_table().at("airlight").spec, "choice(1,1,1, 0.5,0.5,0.5)");
  EXPECT_NE(m.find("colours"), std::string::npos) << m;

  // Names: unknown (with the nearest), duplicated by spelling, unknown effect.
  m = error_of([] { random_params("haze", 1, "k", {{"visiblity", "800"}}); });
  EXPECT_NE(m.find("'visiblity' is not a parameter of haze; did you mean 'visibility'?"), std::string::npos) << m;
  m = error_of([] { random_params("fog", 1, "k", {{"visibility", "800"}}); });
  EXPECT_NE(m.find("'visibility' is not a parameter of fog"), std::string::npos) << m;
  EXPECT_NE(m.find("'visibility' is a parameter of haze"), std::string::npos) << m;
  m = error_of([] { random_params("haze", 1, "k", {{"kappa-s", "0.5"}, {"kappa_s", "0.6"}}); });
  EXPECT_NE(m.find("same parameter"), std::string::npos) << m;
  m = error_of([] { random_params("smoke", 1, "k", {}); });
  EXPECT_NE(m.find("use one of: haze, aerial, fog, dof"), std::string::npos) << m;
  // A combination the effect refuses, named with the key and the effect's own message.
  m = error_of([] { random_params("haze", 1, "Art/view1.png", {{"visibility", "800"}, {"kappa-a", "0.1"}}); });
  EXPECT_NE(m.find("key 'Art/view1.png'"), std::string::npos) << m;
  EXPECT_NE(m.find("--visibility sets the extinction"), std::string::npos) << m;
}

// Defaults that a given parameter takes over are dropped: kappa-s replaces
// haze's visibility (and its albedo), --coc-infinity replaces dof's lens.
TEST(Sample, DefaultsGiveWayAndExtend) {
  const nlohmann::json k = random_params("haze", 1, "k", {{"kappa-s", "uniform(0.1, 1)"}});
  EXPECT_FALSE(k.contains("visibility")) << k.dump();
  EXPECT_FALSE(k.contains("albedo")) << k.dump();
  EXPECT_TRUE(k.contains("lambda")) << k.dump();
  const nlohmann::json d = random_params("dof", 1, "k", {{"coc-infinity", "uniform(0, 12)"}});
  EXPECT_FALSE(d.contains("f-number")) << d.dump();
  EXPECT_TRUE(d.contains("focus-distance")) << d.dump();
  // Extended with a parameter of a nested block (diffusion) and a fixed value.
  const nlohmann::json e = random_params("haze", 1, "k", {{"sigma0", "choice(0.5, 1)"}, {"lambda", "4"}});
  EXPECT_EQ(e["lambda"], 4.0);
  EXPECT_TRUE(e["sigma0"] == 0.5 || e["sigma0"] == 1.0) << e.dump();
  const auto specs = resolve_sample_specs("haze", {{"visibility", " loguniform( 100,2000)"}});
  EXPECT_EQ(specs, (std::map<std::string, std::string>{
                       {"visibility", "loguniform(100, 2000)"}, {"albedo", "uniform(0.8, 1)"}, {"lambda", "uniform(0, 8)"}}));
}

// The dict goes onto the params struct through the table; the record says how it was drawn.
TEST(Sample, ApplyAndProvenance) {
  const nlohmann::json v = random_params("haze", 7, "Art/view1.png", {{"composite", "choice(naive)"}});
  HazeParams p;
  const std::set<std::string> given = apply_params(haze_param_table(), p, v);
  EXPECT_EQ(given, (std::set<std::string>{"visibility", "albedo", "lambda", "composite"}));
  EXPECT_EQ(*p.visibility_m, v["visibility"].get<double>());
  EXPECT_EQ(p.albedo, v["albedo"].get<double>());
  EXPECT_EQ(p.lambda, v["lambda"].get<double>());
  EXPECT_EQ(p.composite, Composite::naive);
  EXPECT_NO_THROW(validate_haze(p, given));
  HazeParams q;
  std::string m = error_of([&] { apply_params(haze_param_table(), q, {{"visibilty", 100.0}}); });
  EXPECT_NE(m.find("did you mean 'visibility'"), std::string::npos) << m;
  m = error_of([&] { apply_params(haze_param_table(), q, {{"albedo", 2.0}}); });
  EXPECT_NE(m.find("--albedo 2 is not allowed"), std::string::npos) << m;

  const nlohmann::json rec = sample_provenance("haze", 7, "Art/view1.png", {{"lambda", "uniform(0,4)"}});
  EXPECT_EQ(rec["sampler"], "brume-sample-v1");
  EXPECT_EQ(rec["seed"], 7);
  EXPECT_EQ(rec["key"], "Art/view1.png");
  EXPECT_EQ(rec["specs"]["lambda"], "uniform(0, 4)");
  EXPECT_EQ(rec["specs"]["visibility"], "loguniform(50, 5000)");
}

TEST(Sample, Cli) {
  CliRun r = run("sample --effect haze --seed 7 --key Art/view1.png");
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j["params"], random_params("haze", 7, "Art/view1.png", {}));
  EXPECT_EQ(j["sampling"]["sampler"], "brume-sample-v1");
  EXPECT_EQ(j["key"], "Art/view1.png");

  r = run("sample --effect haze --seed 7 --key k --count 3 --param 'visibility=loguniform(100, 2000)' --param lambda=2");
  ASSERT_EQ(r.status, 0) << r.output;
  std::istringstream lines(r.output);
  std::string line;
  int i = 0;
  for (; std::getline(lines, line); ++i) {
    const nlohmann::json o = nlohmann::json::parse(line);
    const std::string key = "k#" + std::to_string(i);
    EXPECT_EQ(o["key"], key);
    EXPECT_EQ(o["params"], random_params("haze", 7, key, {{"visibility", "loguniform(100, 2000)"}, {"lambda", "2"}}));
  }
  EXPECT_EQ(i, 3);

  r = run("sample --effect haze --seed 7 --key k --param 'albedo=uniform(-1, 1)'");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--albedo"), std::string::npos) << r.output;
  r = run("sample --effect haze --seed 7 --key k --param visibility");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("NAME=SPEC"), std::string::npos) << r.output;
}

// seed(): a whole-number parameter per key, the hash's top 53 bits (k of u = k·2^-53, exactly);
// refused for any other kind and with arguments; its ends checked by the declaration (0, 2^53 - 1).
TEST(Sample, SeedDrawsTheHashsTop53Bits) {
  const ParamSpec& seed = camera_rain_param_table().at("rain-seed").spec;
  const Distribution d = parse_distribution(seed, " seed ( ) ");
  EXPECT_EQ(d.kind, Distribution::Kind::seed);
  EXPECT_EQ(d.text(), "seed()");
  EXPECT_EQ(draw(d, 0.0), 0u);
  EXPECT_EQ(draw(d, 0x1p-53 * 12345), 12345u);
  EXPECT_EQ(draw(d, 1.0 - 0x1p-53), (std::uint64_t{1} << 53) - 1);
  const nlohmann::json v = random_params("rain", 7, "Art/view1.png", {});
  EXPECT_EQ(v["rain-seed"].get<std::uint64_t>(),
            static_cast<std::uint64_t>(sample_unit(7, "Art/view1.png", "rain-seed") * 0x1p53));
  EXPECT_NE(v["rain-seed"], random_params("rain", 7, "Art/view2.png", {})["rain-seed"]);
  const std::vector<nlohmann::json> ends = sample_corners("rain", {{"rate", "5"}}, 16);
  ASSERT_EQ(ends.size(), 2u);
  EXPECT_EQ(ends[0]["rain-seed"], 0u);
  EXPECT_EQ(ends[1]["rain-seed"], (std::uint64_t{1} << 53) - 1);
  auto err = [](const ParamSpec& s, const std::string& t) { return error_of([&] { parse_distribution(s, t); }); };
  std::string m = err(haze_param_table().at("visibility").spec, "seed()");
  EXPECT_NE(m.find("--visibility"), std::string::npos) << m;
  EXPECT_NE(m.find("whole number"), std::string::npos) << m;
  m = err(seed, "seed(3)");
  EXPECT_NE(m.find("no arguments"), std::string::npos) << m;
}

// Wet ground's sampling (issue #57): the film log-uniform over 0.05-2 mm, the dry albedo uniform over
// 0.05-0.25 and the scan's detection seed per key (seed()); every corner of the ranges passes the
// command's checks; a fixed seed is kept.
TEST(Sample, WetDrawsItsFilmAlbedoAndScanSeedPerKey) {
  const nlohmann::json a = random_params("wet", 7, "frame/0", {}), b = random_params("wet", 7, "frame/1", {});
  ASSERT_EQ(a.size(), 3u) << a.dump();
  EXPECT_TRUE(a["film"].get<double>() >= 0.05 && a["film"].get<double>() < 2.0) << a.dump();
  EXPECT_TRUE(a["ground-albedo"].get<double>() >= 0.05 && a["ground-albedo"].get<double>() < 0.25) << a.dump();
  // loguniform's inverse CDF at the sampler's u (exp/log rounding only)
  const double u = sample_unit(7, "frame/0", "film");
  EXPECT_NEAR(a["film"].get<double>(), 0.05 * std::pow(40.0, u), 1e-12);
  EXPECT_EQ(a["scan-seed"].get<std::uint64_t>(),
            static_cast<std::uint64_t>(sample_unit(7, "frame/0", "scan-seed") * 0x1p53));
  EXPECT_NE(a["scan-seed"], b["scan-seed"]);
  EXPECT_EQ(random_params("wet", 7, "frame/0", {{"scan-seed", "4"}})["scan-seed"], 4u);
  const std::vector<nlohmann::json> ends = sample_corners("wet", {{"scan-seed", "4"}}, 16);
  ASSERT_EQ(ends.size(), 4u);  // the film's two ends by the albedo's two
  for (const nlohmann::json& e : ends) EXPECT_NO_THROW(find_command("wet")->sampling->validate(e)) << e.dump();
}
