// --turbidity contrast (issue #59, brume/aerial.hpp fit_turbidity_contrast):
// the turbidity recovered from a render whose clean scene has the same
// texture at every distance (the fit's one assumption, made true here), on
// the level and the slant path; a scene without haze sits on the lower bound
// and says so; scenes the fit cannot measure are refused; the word parses,
// formats and checks as a parameter value.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "brume/aerial.hpp"
#include "brume/camera.hpp"
#include "brume/error.hpp"
#include "brume/insert.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

constexpr int kRowsW = 192, kRowsH = 160;

// Land from 400 m (bottom row) to 20 km (top row), one range per row (so the
// lower neighbours, 2.5 % apart, are depth edges and every pair measured is
// a pair of the same row), and one random texture repeated on every row: the
// clean scene's contrast is the same at every distance, exactly.
void textured_rows(Image& clean, Image& range) {
  clean = Image(kRowsW, kRowsH, 3);
  range = Image(kRowsW, kRowsH, 1);
  std::mt19937 rng(59);
  std::uniform_real_distribution<float> u(0.05f, 0.5f);  // darker than the airlight: never clipped
  std::vector<float> tex(3 * kRowsW);
  for (float& v : tex) v = u(rng);
  for (int y = 0; y < kRowsH; ++y) {
    const float s = 400.0f * std::pow(50.0f, static_cast<float>(kRowsH - 1 - y) / (kRowsH - 1));
    for (int x = 0; x < kRowsW; ++x) {
      range.at(x, y) = s;
      for (int c = 0; c < 3; ++c) clean.at(x, y, c) = tex[3 * x + c];
    }
  }
}

Image render(const Image& clean, const Image& range, AerialParams p, const AerialGeometry* geo = nullptr) {
  p.airlight = Rgb{0.6f, 0.7f, 0.9f};
  AerialAnalysis a;
  analyse_aerial(clean, range, p, a, 2, geo);
  return apply_aerial(clean, range, p, a).rgb;
}

AerialParams removal() {
  AerialParams p;
  p.remove = true;
  p.atmosphere.turbidity = NAN;
  p.turbidity_rule = "contrast";
  return p;
}

}  // namespace

// The render at T 4 (and T 9) holds exactly the attenuation the fit models;
// what separates the recovered T from the true one is the bin average (the
// fit takes ln of the bin's mean contrast against ln Gamma at the bin's mean
// distance: a Jensen gap of ~beta^2 var(s)/2 in ln Gamma, ~1e-4 here) and the
// render's f32 table: 0.5 % allows both (measured −0.21 % at T 4, −0.30 % at
// T 9: the Jensen gap's sign, clearer air).
TEST(AerialContrast, RecoversTheTurbidityOfALevelRender) {
  Image clean, range;
  textured_rows(clean, range);
  for (double t : {4.0, 9.0}) {
    AerialParams r;
    r.atmosphere = {t, 300.0};
    const Image hazy = render(clean, range, r);
    AerialParams p = removal();
    p.atmosphere.altitude_m = 300.0;
    const TurbidityContrastFit f = fit_turbidity_contrast(hazy, range, p, nullptr, 2);
    std::printf("level T %g: fitted %.5f, spread %.4f over %zu bins\n", t, f.turbidity,
                f.record["turbidity_spread"].get<double>(), f.record["bins"].size());
    EXPECT_NEAR(f.turbidity, t, 0.005 * t) << f.record.dump();
    EXPECT_FALSE(f.at_lower_bound);
    EXPECT_TRUE(f.warning.empty());
    EXPECT_GE(f.record["bins"].size(), 10u);
    EXPECT_LT(f.record["turbidity_spread"].get<double>(), 0.01 * t);
    EXPECT_GT(f.record["excluded_pairs"]["depth_edge"].get<std::size_t>(), 0u);
  }
}

// The slant path: the camera at 2,000 m looking 3 degrees up, the rows'
// targets climbing to ~1 km above it; the render and the fit both take each
// pixel's altitude from its ray. The same tolerance and reason as above, plus
// the bin's mean equivalent distances standing for its pairs' (ln Gamma is
// linear in them at one wavelength).
TEST(AerialContrast, RecoversTheTurbidityOfASlantRender) {
  Image clean, range;
  textured_rows(clean, range);
  AerialParams r;
  r.atmosphere = {3.0, 2000.0};
  r.path = AerialPath::slant;
  r.camera.pitch_deg = 3.0;
  AerialGeometry geo;
  geo.camera = make_camera(Intrinsics{150.0, 150.0, NAN, NAN}, kRowsW, kRowsH, r.camera);
  const Image hazy = render(clean, range, r, &geo);
  AerialParams p = removal();
  p.atmosphere.altitude_m = 2000.0;
  p.path = AerialPath::slant;
  p.camera = r.camera;
  const TurbidityContrastFit f = fit_turbidity_contrast(hazy, range, p, &geo, 2);
  std::printf("slant T 3: fitted %.5f, spread %.4f over %zu bins\n", f.turbidity,
              f.record["turbidity_spread"].get<double>(), f.record["bins"].size());
  EXPECT_NEAR(f.turbidity, 3.0, 0.015) << f.record.dump();
  // The level fit of the same photo misreads it: thinner air above reads as
  // clearer air.
  AerialParams level = removal();
  level.atmosphere.altitude_m = 2000.0;
  EXPECT_LT(fit_turbidity_contrast(hazy, range, level, nullptr, 2).turbidity, 3.0 - 0.1);
}

// No haze at all: the contrast does not fall with distance, which even pure
// air (T = 1, Rayleigh alone) would make it do; the fit sits on T = 1 and
// says so.
// brume insert renders its object into the air the photo shows: with
// --turbidity contrast the fit runs on the photo and its scene range first,
// and the insertion is the one at the fitted T, bit for bit.
TEST(AerialContrast, InsertRendersTheObjectAtTheFittedTurbidity) {
  Image clean, range;
  textured_rows(clean, range);
  AerialParams r;
  r.atmosphere = {6.0, 300.0};
  const Image photo = render(clean, range, r);
  // A grey opaque panel at 2 km over the middle of the frame.
  Image object(kRowsW, kRowsH, 4, 0.0f), object_range(kRowsW, kRowsH, 1, NAN);
  for (int y = 60; y < 100; ++y)
    for (int x = 80; x < 120; ++x) {
      for (int c = 0; c < 3; ++c) object.at(x, y, c) = 0.4f;
      object.at(x, y, 3) = 1.0f;
      object_range.at(x, y) = 2000.0f;
    }
  AerialParams p;
  p.atmosphere.altitude_m = 300.0;
  p.airlight = Rgb{0.6f, 0.7f, 0.9f};
  p.atmosphere.turbidity = NAN;
  p.turbidity_rule = "contrast";
  RangeStep off;
  off.mode = PrepareMode::off;
  const InsertRun fitted = insert_object(photo, range, object, object_range, p, off);
  const double t = fitted.record["turbidity_fit"]["turbidity"].get<double>();
  EXPECT_NEAR(t, 6.0, 0.005 * 6.0) << fitted.record["turbidity_fit"].dump();
  AerialParams at = p;
  at.turbidity_rule.clear();
  at.atmosphere.turbidity = t;
  const InsertRun direct = insert_object(photo, range, object, object_range, at, off);
  EXPECT_EQ(fitted.result.rgb.data, direct.result.rgb.data);
  EXPECT_EQ(fitted.record["insert"], direct.record["insert"]);
}

TEST(AerialContrast, AClearSceneSitsOnTheLowerBoundAndSaysSo) {
  Image clean, range;
  textured_rows(clean, range);
  const TurbidityContrastFit f = fit_turbidity_contrast(clean, range, removal(), nullptr, 1);
  EXPECT_EQ(f.turbidity, 1.0);
  EXPECT_TRUE(f.at_lower_bound);
  EXPECT_TRUE(f.record["at_lower_bound"].get<bool>());
  EXPECT_NE(f.warning.find("lower bound T = 1"), std::string::npos) << f.warning;
}

TEST(AerialContrast, RefusesWhatItCannotMeasure) {
  Image clean, range;
  textured_rows(clean, range);
  // One distance: no decay to measure.
  Image one(kRowsW, kRowsH, 1, 5000.0f);
  std::string e = error_of([&] { fit_turbidity_contrast(clean, one, removal(), nullptr, 1); });
  EXPECT_NE(e.find("needs textured land over a range of distances"), std::string::npos) << e;
  EXPECT_NE(e.find("give --turbidity T"), std::string::npos) << e;
  // A flat colour: no contrast at any distance.
  Image flat(kRowsW, kRowsH, 3, 0.3f);
  e = error_of([&] { fit_turbidity_contrast(flat, range, removal(), nullptr, 1); });
  EXPECT_NE(e.find("found 0 distance bins"), std::string::npos) << e;
  // Only a removal has a photo's turbidity to fit.
  AerialParams render_p = removal();
  render_p.remove = false;
  e = error_of([&] { validate_aerial(render_p); });
  EXPECT_NE(e.find("only --remove takes"), std::string::npos) << e;
  render_p.from_turbidity = 3.0;
  e = error_of([&] { validate_aerial(render_p); });
  EXPECT_NE(e.find("--from-turbidity"), std::string::npos) << e;
  // The analysis takes a number: the library caller fits first.
  e = error_of([&] { analyse_aerial(clean, range, removal(), 1); });
  EXPECT_NE(e.find("fit_turbidity_contrast"), std::string::npos) << e;
}

// The word is a value of --turbidity like a number: parsed, checked,
// formatted, and kept through the table's JSON.
TEST(AerialContrast, TheWordIsAParameterValue) {
  const ParamSpec* s = &aerial_param_table().at("turbidity").spec;
  EXPECT_EQ(s->parse("contrast"), nlohmann::json("contrast"));
  EXPECT_EQ(s->parse("auto"), nlohmann::json());
  EXPECT_EQ(s->parse("3.5"), nlohmann::json(3.5));
  EXPECT_EQ(s->format(nlohmann::json("contrast")), "contrast");
  EXPECT_NO_THROW(s->check(nlohmann::json("contrast")));
  const std::string e = error_of([&] { s->check(nlohmann::json("sky")); });
  EXPECT_NE(e.find("'sky' is not allowed"), std::string::npos) << e;
  EXPECT_NE(s->describe().find("| contrast"), std::string::npos) << s->describe();
  AerialParams p = removal();
  const nlohmann::json j = aerial_param_table().to_json(p);
  EXPECT_EQ(j["aerial"]["turbidity"], "contrast");
  AerialParams back;
  aerial_param_table().from_json(back, j, "job");
  EXPECT_EQ(back.turbidity_rule, "contrast");
  EXPECT_TRUE(std::isnan(back.atmosphere.turbidity));
  back.turbidity_rule.clear();
  aerial_param_table().from_json(back, aerial_param_table().to_json(AerialParams{}), "job");
  EXPECT_EQ(back.atmosphere.turbidity, 2.0);
  EXPECT_TRUE(back.turbidity_rule.empty());
}
