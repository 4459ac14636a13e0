// Parameter declarations (brume/params.hpp): every flag of every command is
// declared completely (unit, range, help), every range check names its flag,
// records round-trip, and the rules a run would otherwise silently bend
// (preparation flags with --prepare off, kappa with visibility) are refused.
#include <gtest/gtest.h>

#include <set>

#include "brume/aerial.hpp"
#include "brume/aerial_coefficients.hpp"
#include "brume/blur.hpp"
#include "brume/chain.hpp"
#include "brume/compare.hpp"
#include "depth/commands/depth_jobs.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/haze.hpp"
#include "brume/insert.hpp"
#include "brume/sky.hpp"
#include "brume/pipeline.hpp"
#include "effects/aerial/aerial_job.hpp"
#include "effects/aerial/coefficients/coefficients_job.hpp"
#include "effects/aerial/insert/insert_job.hpp"
#include "effects/blur/blur_job.hpp"
#include "effects/dof/chain/chain_job.hpp"
#include "effects/dof/dof_job.hpp"
#include "effects/fog/fog_job.hpp"
#include "effects/haze/haze_job.hpp"
#include "effects/sky/sky_job.hpp"
#include "test_util.hpp"

using namespace brume;
using brume::test::error_of;

namespace {

template <class P>
void expect_complete(const ParamTable<P>& t, const char* what) {
  std::set<std::string> names;
  const P defaults{};
  for (const auto& d : t.params()) {
    const ParamSpec& s = d.spec;
    SCOPED_TRACE(std::string(what) + " --" + s.name);
    EXPECT_FALSE(s.help.empty());
    EXPECT_FALSE(s.block.empty());
    EXPECT_TRUE(names.insert(s.name).second) << "flag declared twice";
    for (const auto& a : s.aliases) EXPECT_TRUE(names.insert(a).second) << "alias --" << a << " declared twice";
    if (s.kind == ParamKind::real || s.kind == ParamKind::integer || s.kind == ParamKind::rgb) {
      EXPECT_FALSE(s.unit.empty()) << "numeric parameter without a unit";
      EXPECT_LE(s.range.min, s.range.max);
    }
    if (s.kind == ParamKind::choice) {
      EXPECT_GE(s.choices.size(), 2u);
    }
    // The default itself passes the declaration's own check.
    EXPECT_NO_THROW(s.check(d.get(defaults)));
    // Help text carries the unit and range (or the names).
    const std::string h = s.describe();
    if (!s.unit.empty()) {
      EXPECT_NE(h.find(s.unit), std::string::npos) << h;
    }
    for (const auto& c : s.choices) EXPECT_NE(h.find(c), std::string::npos) << h;
  }
}

// A value outside the declared range is refused with the flag's name.
template <class P>
void expect_range_errors_name_the_flag(const ParamTable<P>& t) {
  for (const auto& d : t.params()) {
    const ParamSpec& s = d.spec;
    std::vector<std::string> bad;
    if (s.kind == ParamKind::real || s.kind == ParamKind::integer) {
      if (std::isfinite(s.range.min)) bad.push_back(std::to_string(s.range.min - 1.0));
      if (std::isfinite(s.range.max)) bad.push_back(std::to_string(s.range.max + 1.0));
      if (s.kind == ParamKind::real) bad.push_back("nan");
      bad.push_back("x1");
    }
    if (s.kind == ParamKind::choice) bad.push_back("no-such-choice");
    if (s.kind == ParamKind::rgb) bad = {"1,2", "1,-1,1", "a,b,c"};
    for (const auto& b : bad) {
      P p{};
      try {
        t.set_text(p, s.name, b);
        ADD_FAILURE() << "--" << s.name << " " << b << " was accepted";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("--" + s.name), std::string::npos) << e.what();
      }
    }
  }
}

}  // namespace

TEST(Params, EveryCommandIsDeclaredCompletely) {
  expect_complete(haze_job_table(), "haze");
  expect_complete(blur_job_table(), "blur");
  expect_complete(depth_convert_job_table(), "depth convert");
  expect_complete(depth_prepare_job_table(), "depth prepare");
  expect_complete(exec_param_table(), "execution");
  expect_complete(camera_pose_param_table(), "camera");
  expect_complete(aerial_job_table(), "aerial");
  expect_complete(coefficients_job_table(), "aerial coefficients");
  expect_complete(compare_job_table(), "compare");
  expect_complete(insert_job_table(), "insert");
  expect_complete(sky_render_job_table(), "sky render");
  expect_complete(sky_fit_job_table(), "sky fit");
  expect_complete(fog_job_table(), "fog");
  expect_complete(dof_job_table(), "dof");
  expect_complete(haze_dof_job_table(), "haze+dof");
}

TEST(Params, RangeErrorsNameTheFlag) {
  expect_range_errors_name_the_flag(haze_job_table());
  expect_range_errors_name_the_flag(blur_job_table());
  expect_range_errors_name_the_flag(depth_prepare_job_table());
  expect_range_errors_name_the_flag(exec_param_table());
  expect_range_errors_name_the_flag(camera_pose_param_table());
  expect_range_errors_name_the_flag(aerial_job_table());
  expect_range_errors_name_the_flag(coefficients_job_table());
  expect_range_errors_name_the_flag(sky_render_job_table());
  expect_range_errors_name_the_flag(sky_fit_job_table());
  expect_range_errors_name_the_flag(insert_job_table());
  expect_range_errors_name_the_flag(fog_job_table());
  expect_range_errors_name_the_flag(dof_job_table());
  expect_range_errors_name_the_flag(haze_dof_job_table());
}

TEST(Params, CameraPoseBlockDrivesTheCamera) {
  // The declared pose block feeds make_camera: pitch 30 raises the optical
  // axis by 30 degrees (closed form: axis y = sin 30), heights are kept.
  CameraPose pose;
  const auto& t = camera_pose_param_table();
  t.set_text(pose, "pitch", "30");
  t.set_text(pose, "camera-height", "1.6");
  Intrinsics k;
  k.fx = k.fy = 100.0;
  const Camera c = make_camera(k, 101, 81, pose);
  EXPECT_NEAR(c.world_ray(50.0, 40.0).y, 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(c.position_m.y, 1.6);
  EXPECT_TRUE(t.to_json(CameraPose{})["camera"]["camera-height"].is_null());  // unknown, not 0
}

TEST(Params, PrepareMessagesUseFlagNamesNotCppNames) {
  PrepareParams p;
  p.sky_margin_px = -1.0;
  try {
    prepare_range(Image(8, 8, 1, 1.0f), p);
    FAIL() << "a negative margin was accepted";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("--sky-margin"), std::string::npos) << m;
    EXPECT_EQ(m.find("PrepareParams"), std::string::npos) << m;
  }
}

TEST(Params, RecordsRoundTrip) {
  HazeJob job;
  const auto& t = haze_job_table();
  t.set_text(job, "visibility", "750");
  t.set_text(job, "albedo", "0.8");
  t.set_text(job, "airlight", "0.7,0.75,0.8");
  t.set_text(job, "scheme", "standard");
  t.set_text(job, "rho-max", "0.125");
  t.set_text(job, "sky-margin", "3.5");
  t.set_text(job, "seed", "7");
  t.set_text(job, "fx", "500");
  t.set_text(job, "far", "inf");
  t.set_text(job, "image", "a.png");
  t.set_text(job, "transmission", "t.exr");
  const nlohmann::json j = t.to_json(job);
  HazeJob back;
  t.from_json(back, j, "test");
  EXPECT_EQ(t.to_json(back), j);
  EXPECT_EQ(*back.haze.visibility_m, 750.0);
  EXPECT_EQ((*back.haze.airlight)[1], 0.75f);
  EXPECT_EQ(back.haze.diffusion.scheme, Scheme::standard);
  EXPECT_EQ(*back.haze.diffusion.rho_max, 0.125);
  EXPECT_EQ(back.prepare.params.seed, 7u);
  EXPECT_EQ(back.input.depth.k.fx, 500.0);
  EXPECT_TRUE(std::isinf(back.input.depth.far_m));
  EXPECT_EQ(back.output.maps.at("transmission"), "t.exr");
  // Unset optionals are null, not a 0 sentinel.
  EXPECT_TRUE(j["haze"]["range-max"].is_null());
  EXPECT_TRUE(j["depth"]["cx"].is_null());
  // An undeclared key is refused, naming it.
  nlohmann::json bad = j;
  bad["haze"]["kappa"] = 1.0;
  try {
    t.from_json(back, bad, "record");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("haze.kappa"), std::string::npos) << e.what();
  }
}

TEST(Params, IgnoredCombinationsAreRefused) {
  HazeParams p;
  p.visibility_m = 500.0;
  p.kappa_s = 0.5;
  EXPECT_THROW(validate_haze(p), Error);  // kappa would be ignored
  HazeParams q;
  q.albedo = 0.5;
  EXPECT_THROW(validate_haze(q), Error);  // albedo needs visibility
  HazeParams r;
  r.visibility_m = 500.0;
  EXPECT_THROW(validate_haze(r, {"kappa-s"}), Error);  // given explicitly, even at its default value
  RangeStep off;
  off.mode = PrepareMode::off;
  EXPECT_NO_THROW(check_range_step(off));
  EXPECT_THROW(check_range_step(off, {"sky-margin"}), Error);
  off.params.s_max_factor = 2.0;
  EXPECT_THROW(check_range_step(off), Error);
}

TEST(Params, OptionalsTakeTheirUnsetWord) {
  HazeParams p;
  const auto& t = haze_param_table();
  t.set_text(p, "range-max", "40");
  ASSERT_TRUE(p.range_max_m.has_value());
  t.set_text(p, "range-max", "auto");
  EXPECT_FALSE(p.range_max_m.has_value());
  // 0 is no longer a sentinel for "auto": it is out of range.
  EXPECT_THROW(t.set_text(p, "range-max", "0"), Error);
  EXPECT_THROW(t.set_text(p, "rho-max", "0"), Error);
}

// A real flag takes a ratio p/q (Middlebury's third-size disparities:
// --disparity-scale 1/3), kept as the quotient; what is not one number nor
// one ratio of finite numbers with q != 0 stays an error.
TEST(Params, ARealTakesARatio) {
  HazeParams p;
  const auto& t = haze_param_table();
  t.set_text(p, "range-max", "200/3");
  ASSERT_TRUE(p.range_max_m.has_value());
  EXPECT_EQ(*p.range_max_m, 200.0 / 3.0);
  for (const char* bad : {"1/0", "1/", "/3", "1/3/2", "inf/2", "1/nan", "a/b"})
    EXPECT_THROW(t.set_text(p, "range-max", bad), Error) << bad;
}

// The output block marks the parameters that name files it writes (brume
// batch renames them after the key, brume run moves them): --out, --record
// and every declared map, never a setting such as --compression or --bits.
TEST(Params, OutputFilesAreMarkedBySpecNotByName) {
  const std::vector<MapOutput> maps = {MapOutput{"transmission", "T map", ""},
                                       MapOutput{"sigma", "blur scale map", "values in px"}};
  std::set<std::string> files, settings;
  for (const auto& d : output_param_table(maps).params()) (is_output_file(d.spec) ? files : settings).insert(d.spec.name);
  EXPECT_EQ(files, (std::set<std::string>{"out", "record", "transmission", "sigma"}));
  EXPECT_EQ(settings, (std::set<std::string>{"bits", "out-transfer", "compression", "out-alpha", "keep-layers"}));
  // The depth commands' own output blocks: exactly what the name rule gave
  // before the flag (their text parameters of the output block).
  std::set<std::string> conv, prep;
  for (const auto& d : depth_convert_job_table().params())
    if (is_output_file(d.spec)) conv.insert(d.spec.name);
  for (const auto& d : depth_prepare_job_table().params())
    if (is_output_file(d.spec)) prep.insert(d.spec.name);
  EXPECT_EQ(conv, (std::set<std::string>{"out", "record"}));
  EXPECT_EQ(prep, (std::set<std::string>{"out", "masks", "record"}));
}

// A colour that may be a named rule instead (aerial's --airlight horizon): the
// word parses, checks, formats and round-trips through the record as itself,
// a colour as a colour, and any other word is refused naming the words.
TEST(Params, AColourOrAWord) {
  const auto& t = aerial_param_table();
  const ParamSpec& s = t.at("airlight").spec;
  EXPECT_EQ(s.parse("horizon"), "horizon");
  EXPECT_EQ(s.parse("0.5,0.6,0.7"), nlohmann::json({0.5f, 0.6f, 0.7f}));
  EXPECT_TRUE(s.parse("auto").is_null());
  EXPECT_EQ(s.format("horizon"), "horizon");
  EXPECT_NO_THROW(s.check("horizon"));
  const std::string e = error_of([&] { s.check("sunset"); });
  EXPECT_NE(e.find("--airlight 'sunset'"), std::string::npos) << e;
  EXPECT_NE(e.find("horizon"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { s.parse("sunset"); }).find("horizon"), std::string::npos);
  AerialParams p;
  t.from_json(p, {{"aerial", {{"airlight", "horizon"}}}}, "test");
  EXPECT_EQ(p.airlight_rule, "horizon");
  EXPECT_FALSE(p.airlight);
  EXPECT_EQ(t.to_json(p)["aerial"]["airlight"], "horizon");
  t.from_json(p, {{"aerial", {{"airlight", {0.1, 0.2, 0.3}}}}}, "test");
  EXPECT_EQ(p.airlight_rule, "");
  ASSERT_TRUE(p.airlight);
  EXPECT_EQ(t.to_json(p)["aerial"]["airlight"], nlohmann::json({0.1f, 0.2f, 0.3f}));
}
