// Wet ground (issue #57, brume/wet.hpp): the film's optics against independent forms, the
// camera's darkening and mirror image, the LiDAR's ground returns.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <vector>

#include "brume/camera.hpp"
#include "brume/demo_scene.hpp"
#include "brume/error.hpp"
#include "brume/wet.hpp"
#include "core/simd.hpp"
#include "effects/wet/wet_march.hpp"
#include "wet_demo.hpp"

using namespace brume;

namespace {

// Fresnel in the textbook angle form (Born & Wolf 1.5 (21a)): an independent path.
double fresnel_angles(double theta_i, double n) {
  if (theta_i == 0.0) return std::pow((n - 1.0) / (n + 1.0), 2);
  const double tt = std::asin(std::sin(theta_i) / n);
  const double rs = std::pow(std::sin(theta_i - tt) / std::sin(theta_i + tt), 2);
  const double rp = std::pow(std::tan(theta_i - tt) / std::tan(theta_i + tt), 2);
  return 0.5 * (rs + rp);
}

// r_e by the midpoint rule in θ (2·10^5 nodes: error ~1e-11), from the angle form.
double r_e_midpoint(double n) {
  static std::map<double, double> memo;  // the suites ask for three indices
  if (auto it = memo.find(n); it != memo.end()) return it->second;
  const int m = 200000;
  const double h = (M_PI / 2) / m;
  double s = 0.0;
  for (int i = 0; i < m; ++i) {
    const double t = (i + 0.5) * h;
    s += fresnel_angles(t, n) * 2.0 * std::sin(t) * std::cos(t) * h;
  }
  return memo[n] = s;
}

double lekner_dorf(double a, double n) {
  const double re = r_e_midpoint(n), ri = 1.0 - (1.0 - re) / (n * n);
  return (1.0 - re) * (1.0 - ri) / (1.0 - a * ri);
}

// Whether the mirrored ray of a ground pixel (its world ray `ray`, range r) leaves the frame
// through its top without passing behind a pixel's range (by 1 %, the renderer's margin):
// marched in world space, steps of 0.5 % of the distance (independent of the screen-space march).
bool leaves_through_top(const Camera& cam, const Image& range, const Vec3& ray, double r) {
  const Vec3 c = cam.position_m;
  const Vec3 p{c.x + r * ray.x, 0.0, c.z + r * ray.z}, m{ray.x, -ray.y, ray.z};
  for (double t = 0.01;; t += std::max(0.01, 0.005 * (r + t))) {
    const Vec3 q{p.x + t * m.x, p.y + t * m.y, p.z + t * m.z};
    const auto px = cam.pixel_of(q);
    if (!px) return false;
    const double u = (*px)[0], v = (*px)[1];
    if (v < -0.5) return u >= -0.5 && u < cam.width - 0.5;
    if (u < -0.5 || u >= cam.width - 0.5 || v >= cam.height - 0.5) return false;
    const float rs = range.at(static_cast<int>(std::lround(u)), static_cast<int>(std::lround(v)));
    const double dist = std::sqrt((q.x - c.x) * (q.x - c.x) + (q.y - c.y) * (q.y - c.y) + (q.z - c.z) * (q.z - c.z));
    if (std::isfinite(rs) && dist > rs * 1.01) return false;
  }
}

WetFilm film(double mm, double albedo = 0.12, double rough = 1.0) {
  WetFilm w;
  w.film_mm = mm;
  w.ground_albedo = albedo;
  w.roughness_mm = rough;
  return w;
}

}  // namespace

TEST(WetOptics, FresnelIdentitiesPerPolarisation) {
  // R + T = 1 per polarisation: R and T come from different expressions, so rounding alone (1e-12).
  for (double n : {1.2, 1.333, 1.5})
    for (int i = 0; i <= 90; ++i) {
      const double c = std::cos(i * M_PI / 180.0);
      const Fresnel f = fresnel_air_to(c, n);
      EXPECT_NEAR(f.rs + f.ts, 1.0, 1e-12) << n << " " << i;
      EXPECT_NEAR(f.rp + f.tp, 1.0, 1e-12) << n << " " << i;
      // Against the angle form (a different path through the same law): 1e-12.
      if (i < 90) {
        EXPECT_NEAR(f.r(), fresnel_angles(i * M_PI / 180.0, n), 1e-12) << n << " " << i;
      }
    }
  EXPECT_NEAR(fresnel_reflectance(1.0, 1.333), std::pow(0.333 / 2.333, 2), 1e-15);
  EXPECT_NEAR(fresnel_reflectance(0.0, 1.333), 1.0, 1e-15);  // grazing: a mirror
}

TEST(WetOptics, LeknerDorfFromIndependentIntegral) {
  // r_e by Gauss-Legendre against the midpoint rule on the angle form (1e-9: the midpoint's error).
  for (double n : {1.2, 1.333, 1.5}) EXPECT_NEAR(water_diffuse_external_reflectance(n), r_e_midpoint(n), 1e-9);
  const double re = water_diffuse_external_reflectance(1.333);
  EXPECT_NEAR(re, 0.0664, 1e-4);  // water's diffuse reflectance, 0.066 (docs/wet-ground.md)
  EXPECT_NEAR(water_diffuse_internal_reflectance(1.333), 1.0 - (1.0 - re) / (1.333 * 1.333), 1e-15);
  for (double a : {0.05, 0.12, 0.5, 1.0}) {
    const WetOptics o(film(2.0, a));
    EXPECT_NEAR(o.k, lekner_dorf(a, 1.333), 1e-9) << a;
    EXPECT_EQ(o.f, 1.0);
    EXPECT_EQ(o.k_eff, o.k);
  }
  // The camera and the LiDAR use one transfer: diffuse in and out is K.
  EXPECT_EQ(film_transfer(1.0 - re, 1.0 - re, 1.333, 0.12, water_diffuse_internal_reflectance(1.333)), WetOptics(film(2.0)).k);
  // Wetted fraction: linear up to the roughness depth, 0 for no film.
  EXPECT_EQ(wetted_fraction(0.25, 1.0), 0.25);
  EXPECT_EQ(wetted_fraction(3.0, 1.0), 1.0);
  const WetOptics half(film(0.5));
  EXPECT_NEAR(half.k_eff, 1.0 - 0.5 * (1.0 - half.k), 1e-15);
  const WetOptics dry(film(0.0));
  EXPECT_EQ(dry.k_eff, 1.0);
  EXPECT_EQ(dry.mirror(0.3), 0.0);
  EXPECT_EQ(dry.lidar(0.3), 1.0);
  EXPECT_THROW(validate_wet_film(WetFilm{}), Error);  // no --film
}

namespace {

// A flat ground (y = 0) with a bright box on it, seen from height h pitched down: range and
// colour by ray casting in double; sky: NaN range, colour 0.
struct BoxScene {
  int W = 200, H = 150;
  Camera cam;
  Image rgb, range;
  double bx0 = -1.0, bx1 = 1.0, by1 = 2.0, bz0 = -14.0, bz1 = -12.0;
  // The ray (origin o, direction d, world) meets the box: its parameter, else inf.
  double box_hit(const Vec3& o, const Vec3& d) const {
    double t0 = 0.0, t1 = INFINITY;
    const double lo[3] = {bx0, 0.0, bz0}, hi[3] = {bx1, by1, bz1};
    const double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
    for (int k = 0; k < 3; ++k) {
      if (dd[k] == 0.0) {
        if (oo[k] < lo[k] || oo[k] > hi[k]) return INFINITY;
        continue;
      }
      double a = (lo[k] - oo[k]) / dd[k], b = (hi[k] - oo[k]) / dd[k];
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a), t1 = std::min(t1, b);
    }
    return t0 <= t1 ? t0 : INFINITY;
  }
  BoxScene() {
    CameraPose p;
    p.height_m = 1.5;
    p.pitch_deg = -10.0;
    cam = make_camera(intrinsics_from_fov(W, H, NAN, 50.0), W, H, p);
    rgb = Image(W, H, 3);
    range = Image(W, H, 1);
    const Vec3 c = cam.position_m;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 d = cam.world_ray(x, y);
        const double tb = box_hit(c, d), tg = d.y < 0.0 ? -c.y / d.y : INFINITY;
        const double t = std::min(tb, tg);
        range.at(x, y) = std::isfinite(t) ? static_cast<float>(t) : NAN;
        const float v = tb <= tg && std::isfinite(tb) ? 1.0f : std::isfinite(tg) ? 0.1f : 0.0f;
        for (int k = 0; k < 3; ++k) rgb.at(x, y, k) = v;
      }
  }
};

}  // namespace

TEST(WetCamera, BrightBoxMirrorImageWithinOnePixel) {
  // The box's front face carries its pixel's coordinates as colour (R = u/W, G = v/H), so the
  // mirror image says which pixel each ground pixel's reflected ray took. Against the reflected
  // ray cast analytically in double: where it meets the box and the box shows, the pixel taken
  // lies within 1 px (per axis) of the hit's projection (the target; the range map is
  // read at the nearest pixel). Shown where the ray misses, or missing where it meets the box,
  // only within 2 px of the analytic edge: a ray passing within a pixel of the box's edge reads
  // the pixel beside it, and one passing just beside the box, behind it as the camera sees it,
  // cannot be told in screen space from one that meets it (the range map has no thickness).
  // Both marches (WetMarch: every pixel asked; the plane's pixels left out above the tolerance)
  // meet the same analytic truth.
  BoxScene s;
  for (int y = 0; y < s.H; ++y)
    for (int x = 0; x < s.W; ++x)
      if (s.rgb.at(x, y, 0) == 1.0f) s.rgb.at(x, y, 0) = (x + 0.5f) / s.W, s.rgb.at(x, y, 1) = (y + 0.5f) / s.H;
  for (const WetMarch march : {WetMarch::blocks, WetMarch::above_ground}) {
  SCOPED_TRACE(enum_name(wet_march_names(), march));
  WetScene sc;
  sc.rgb = s.rgb;
  sc.range = s.range;
  sc.camera = s.cam;
  sc.ground_tolerance_m = 0.01;
  sc.march = march;
  Exec exec;
  exec.threads = 1;
  Image ground;
  const WetFilm w = film(2.0);
  const Image out = render_wet(sc, w, exec, nullptr, &ground);
  const WetOptics o(w);
  Image expect(s.W, s.H, 1, -1.0f);
  int hits = 0, shown = 0;
  double worst = 0.0;
  for (int y = 0; y < s.H; ++y)
    for (int x = 0; x < s.W; ++x) {
      if (ground.at(x, y) == 0.0f) continue;
      const Vec3 d = s.cam.world_ray(x, y);
      const double r = s.range.at(x, y);
      const Vec3 p{s.cam.position_m.x + r * d.x, 0.0, s.cam.position_m.z + r * d.z}, m{d.x, -d.y, d.z};
      const double t = s.box_hit(p, m);
      expect.at(x, y) = std::isfinite(t) ? 1.0f : 0.0f;
      const double wt = o.mirror(-d.y);
      const double lb = (out.at(x, y, 2) - o.k_eff * 0.1) / wt;  // the blue of what the mirror took
      if (!std::isfinite(t)) continue;
      ++hits;
      if (lb < 0.5) continue;  // shows no box: a miss, checked below
      const auto px = s.cam.pixel_of(Vec3{p.x + t * m.x, p.y + t * m.y, p.z + t * m.z});
      ASSERT_TRUE(px.has_value());
      EXPECT_NEAR(lb, 1.0, 1e-3) << "pixel " << x << "," << y << " takes a mix";
      const double u = (out.at(x, y, 0) - o.k_eff * 0.1) / wt * s.W - 0.5;
      const double v = (out.at(x, y, 1) - o.k_eff * 0.1) / wt * s.H - 0.5;
      const double e = std::max(std::fabs(u - (*px)[0]), std::fabs(v - (*px)[1]));  // per axis
      worst = std::max(worst, e);
      ++shown;
      EXPECT_LE(e, 1.0) << "pixel " << x << "," << y << " took " << u << "," << v << ", the hit is at " << (*px)[0]
                        << "," << (*px)[1];
    }
  ASSERT_GT(hits, 200) << "the box's mirror image must cover part of the ground";
  int wrong = 0, mismatched = 0;
  for (int y = 0; y < s.H; ++y)
    for (int x = 0; x < s.W; ++x) {
      if (expect.at(x, y) < 0.0f) continue;
      const double wt = o.mirror(-s.cam.world_ray(x, y).y);
      const float shows = (out.at(x, y, 2) - o.k_eff * 0.1) > 0.5 * wt ? 1.0f : 0.0f;
      if (shows == expect.at(x, y)) continue;
      ++mismatched;
      bool near_edge = false;  // within 2 px of a ground pixel whose analytic answer differs
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const int a = x + dx, b = y + dy;
          if (a >= 0 && b >= 0 && a < s.W && b < s.H && expect.at(a, b) == 1.0f - expect.at(x, y)) near_edge = true;
        }
      EXPECT_TRUE(near_edge) << "pixel " << x << "," << y << (shows ? " shows" : " misses") << " the box";
      if (!near_edge && ++wrong > 5) return;
    }
  std::printf("box, %s: %d ground pixels' rays meet the box, %d show it within %.3f px; %d differ at the edge\n",
              enum_name(wet_march_names(), march).c_str(), hits, shown, worst, mismatched);
  }
}

TEST(WetCamera, DemoSceneFitsLeknerDorfAndFilmZeroIsIdentity) {
  // The demo scene (camera 1.6 m up, 5 deg down, 55 deg vertical field of view): ground pixels
  // whose mirrored ray leaves through the top fit wet = K dry + R_F(theta) L_c with one K within
  // 5 % of Lekner & Dorf (independent integral), residual <= 4 % of the mean; off the ground unchanged.
  const int W = 256, H = 144;
  const DemoScene d = render_demo_scene(W, H);
  const WetScene sc = test::demo_wet_scene(d, W, H);
  Exec exec;
  exec.threads = 2;
  Image ground;
  const WetFilm w = film(1.5, 0.12, 1.0);
  const Image out = render_wet(sc, w, exec, nullptr, &ground);
  const double top = std::atan(((H - 1) / 2.0 + 0.5) / sc.camera.k.fy) * 180.0 / M_PI - 5.0;  // the top edge's elevation
  double sxy = 0.0, sxx = 0.0, mean = 0.0;
  std::vector<std::array<double, 2>> pts;
  std::size_t off = 0, changed = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (ground.at(x, y) == 0.0f) {
        ++off;
        for (int c = 0; c < 3; ++c) {
          const float a = out.at(x, y, c), b = d.rgb.at(x, y, c);
          changed += std::memcmp(&a, &b, sizeof(float)) != 0;
        }
        continue;
      }
      const Vec3 ray = sc.camera.world_ray(x, y);
      const double elev = std::asin(-ray.y) * 180.0 / M_PI;  // the mirrored ray's elevation
      if (elev < top + 1.0 || !leaves_through_top(sc.camera, d.range, ray, d.range.at(x, y))) continue;
      const double rf = fresnel_angles(std::acos(-ray.y), 1.333);
      for (int c = 0; c < 3; ++c) {
        const double dry = d.rgb.at(x, y, c), wet = out.at(x, y, c) - rf * sc.sky[c];
        sxy += dry * wet, sxx += dry * dry, mean += out.at(x, y, c);
        pts.push_back({dry, wet});
      }
    }
  ASSERT_GT(pts.size(), 3000u);
  EXPECT_EQ(changed, 0u) << "of " << off << " pixels off the ground";
  const double k = sxy / sxx;
  mean /= static_cast<double>(pts.size());
  double ss = 0.0;
  for (const auto& q : pts) ss += (q[1] - k * q[0]) * (q[1] - k * q[0]);
  const double resid = std::sqrt(ss / static_cast<double>(pts.size()));
  const double ld = lekner_dorf(0.12, 1.333);
  EXPECT_NEAR(k / ld, 1.0, 0.05) << "K " << k << " Lekner-Dorf " << ld;
  EXPECT_LE(resid, 0.04 * mean);
  std::printf("demo: K %.5f, Lekner-Dorf %.5f (%+.2f %%), residual %.2f %% of the mean over %zu values\n", k, ld,
              100.0 * (k / ld - 1.0), 100.0 * resid / mean, pts.size());
  // Film 0: the image back bit for bit.
  const Image same = render_wet(sc, film(0.0), exec);
  EXPECT_EQ(std::memcmp(same.data.data(), d.rgb.data.data(), d.rgb.data.size() * sizeof(float)), 0);
  // The image and the range as strided views (an RGBA buffer's RGB, the range as a second channel
  // of two): the same image bit for bit (render_wet reads them row by row where they are dense).
  Image rgba(W, H, 4), range2(W, H, 2);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      for (int c = 0; c < 3; ++c) rgba.at(x, y, c) = d.rgb.at(x, y, c);
      rgba.at(x, y, 3) = 0.5f, range2.at(x, y, 0) = -7.0f, range2.at(x, y, 1) = d.range.at(x, y);
    }
  WetScene strided = sc;
  strided.rgb = ConstImageView(rgba.data.data(), W, H, 3, 4 * W, 4);
  strided.range = ConstImageView(range2.data.data() + 1, W, H, 1, 2 * W, 2);
  EXPECT_EQ(render_wet(strided, w, exec).data, out.data);
}

TEST(WetCamera, AboveGroundMarchAgreesWithBlocksOffThePlane) {
  // The two marches on the demo scene: the same ground, the same pixels off it (bit for bit), and
  // on it the same mirror image but where a ray's hit moves (the w sequence differs where the
  // plane's pixels are left out, and a ray above the tolerance no longer meets the plane's own
  // pixels). Bound: at most 0.2 % of the ground pixels differ by more than 1e-3 (measured 0.02 %:
  // the printout), and their mean difference stays below 1e-3 of the image's mean. Without the
  // camera's height (a mask gives the ground) the plane is unknown: blocks runs, and says so.
  const int W = 400, H = 224;
  const DemoScene d = render_demo_scene(W, H);
  WetScene sc = test::demo_wet_scene(d, W, H);
  sc.ground_tolerance_m = 0.15;  // brume wet's default
  Exec exec;
  exec.threads = 2;
  Image g_old, g_new;
  WetStats s_old, s_new;
  const WetFilm w = film(1.5, 0.12, 1.0);
  sc.march = WetMarch::blocks;
  const Image a = render_wet(sc, w, exec, &s_old, &g_old);
  sc.march = WetMarch::above_ground;
  const Image b = render_wet(sc, w, exec, &s_new, &g_new);
  EXPECT_EQ(s_old.march, WetMarch::blocks);
  EXPECT_EQ(s_new.march, WetMarch::above_ground);
  ASSERT_EQ(g_old.data, g_new.data);
  ASSERT_GT(s_new.ground, 10000u);
  std::size_t differ = 0;
  double sum = 0.0, mean = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      double e = 0.0;
      for (int c = 0; c < 3; ++c) {
        e = std::max(e, static_cast<double>(std::fabs(a.at(x, y, c) - b.at(x, y, c))));
        mean += a.at(x, y, c);
      }
      if (g_old.at(x, y) == 0.0f) {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(a.at(x, y, c), b.at(x, y, c)) << x << "," << y;
        continue;
      }
      differ += e > 1e-3;
      sum += e;
    }
  mean /= 3.0 * W * H;
  const double share = static_cast<double>(differ) / static_cast<double>(s_new.ground);
  std::printf("marches: %zu of %zu ground pixels differ by > 1e-3 (%.3f %%), mean |diff| %.2e (image mean %.3f); "
              "hits %zu vs %zu, sky %zu vs %zu, leave %zu vs %zu\n",
              differ, s_new.ground, 100.0 * share, sum / s_new.ground, mean, s_old.hits, s_new.hits, s_old.sky_pixels,
              s_new.sky_pixels, s_old.left_frame, s_new.left_frame);
  EXPECT_LE(share, 0.002);
  EXPECT_LE(sum / s_new.ground, 1e-3 * mean);
  // A mask without the camera's height: the plane's pixels are not known, the blocks march runs.
  sc.camera.position_m.y = NAN;
  sc.mask = ConstImageView(g_old);
  WetStats s_mask;
  const Image m = render_wet(sc, w, exec, &s_mask);
  EXPECT_EQ(s_mask.march, WetMarch::blocks);
  EXPECT_EQ(s_mask.ground, s_old.ground);
  EXPECT_EQ(m.data, a.data);  // the same ground by the mask, the same march: the same image
}

TEST(WetCamera, MarchSideBySideGivesTheSameBits) {
  // The march runs several rays side by side where a vector holds 8 doubles (AVX-512:
  // effects/wet/wet_march.cpp), a ray at a time elsewhere (wet.cpp's loop, the same code for every
  // narrower target); both must give the same image bit for bit. The best SIMD target this CPU
  // runs (simd::targets(), best first) against the baseline fallback (last: a ray at a time) on
  // the demo scene, both marches: the image and the counts. On a CPU without AVX-512 both run a
  // ray at a time and the test shows only that. (The pixels around the march run side by side on
  // every target: PixelKernelsGiveTheScalarBits checks each against the scalar expressions.)
  const int W = 256, H = 144;
  const DemoScene d = render_demo_scene(W, H);
  WetScene sc = test::demo_wet_scene(d, W, H);
  sc.ground_tolerance_m = 0.15;
  Exec exec;
  exec.threads = 2;
  const WetFilm w = film(1.5, 0.12, 1.0);
  const std::vector<std::int64_t> targets = simd::targets();
  ASSERT_FALSE(targets.empty());
  for (const WetMarch m : {WetMarch::blocks, WetMarch::above_ground}) {
    sc.march = m;
    simd::force_target(targets.back());
    WetStats ref_st;
    const Image ref = render_wet(sc, w, exec, &ref_st);
    ASSERT_GT(ref_st.hits, 5000u);  // every end a ray can have, and many
    ASSERT_GT(ref_st.sky_pixels, 500u);
    ASSERT_GT(ref_st.left_frame, 5000u);
    for (const std::int64_t t : {targets.front(), targets.back()}) {
      SCOPED_TRACE(simd::target_name(t) + ", " + enum_name(wet_march_names(), m));
      simd::force_target(t);
      WetStats st;
      const Image got = render_wet(sc, w, exec, &st);
      const bool same = std::memcmp(got.data.data(), ref.data.data(), ref.data.size() * sizeof(float)) == 0;
      EXPECT_TRUE(same);
      EXPECT_EQ(st.hits, ref_st.hits);
      EXPECT_EQ(st.sky_pixels, ref_st.sky_pixels);
      EXPECT_EQ(st.left_frame, ref_st.left_frame);
      std::printf("wet march, %s, %s: %zu hits, %zu sky, %zu leave, %s\n", simd::target_name(t).c_str(),
                  enum_name(wet_march_names(), m).c_str(), st.hits, st.sky_pixels, st.left_frame,
                  same ? "the same bits" : "OTHER BITS");
    }
  }
  simd::force_target(0);
}

TEST(WetCamera, PixelKernelsGiveTheScalarBits) {
  // render_wet's pixels around the march run side by side (wet_depth_row, wet_setup_rays:
  // effects/wet/wet_march.cpp, compiled for every target) and must give what the scalar
  // expressions they replaced gave (render_wet's loops before 2026-12-07, written out below), bit
  // for bit, on every target this CPU runs: the planar depth, the depth without the plane's pixels,
  // the ground flags, every field of the rays and the mirror's weight (WetOptics::mirror: the
  // library's scalar Fresnel). A tilted camera (pitch and roll: the plane's normal has three
  // components in the camera's frame), rows of 61 pixels (each row's last vector partial), ranges
  // on the plane, near it, far, and unknown (inf, NaN, 0, negative). (It caught Highway's one-lane
  // DemoteTo, which turns inf into the largest float.)
  const int W = 61, H = 40;
  CameraPose pose;
  pose.height_m = 1.6, pose.pitch_deg = -7.0, pose.roll_deg = 4.0;
  const Camera cam = make_camera(intrinsics_from_fov(W, H, 70.0, NAN), W, H, pose);
  const Mat3 R = cam.world_from_camera().rotation;
  const WetOptics o(film(0.6, 0.12, 1.0));
  ASSERT_GT(o.f, 0.0);
  ASSERT_LT(o.f, 1.0);
  detail::WetPixelFrame f;
  f.fx = cam.k.fx, f.fy = cam.k.fy, f.cx = cam.k.cx, f.cy = cam.k.cy;
  f.nx = R.m[1][0], f.ny = R.m[1][1], f.nz = R.m[1][2], f.h = cam.position_m.y, f.tol = 0.15;
  f.f = o.f, f.n = o.n, f.step_px = kWetMarchStepPx, f.lift = true;
  Image range(W, H, 1);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const Vec3 d = cam.world_ray(x, y);
      const double t = d.y < 0.0 ? 1.6 / -d.y : 40.0;  // along the ray to the plane
      const float unknown[4] = {INFINITY, NAN, 0.0f, -1.0f};
      const int k = (3 * x + y) % 6;
      range.at(x, y) = k < 2 ? static_cast<float>(t * (k == 0 ? 1.0 : 1.08)) : k < 5 ? static_cast<float>(2.0 + 0.37 * x + 0.11 * y)
                                                                                   : unknown[(x + y) % 4];
    }
  // the scalar expressions
  std::vector<float> z_ref(W * H), zo_ref(W * H);
  std::vector<std::uint8_t> fl_ref(W * H);
  std::vector<std::int32_t> px, py;
  std::vector<float> pz;
  std::vector<std::array<double, 8>> ray_ref;  // w0, dw, uinf, vinf, cu, cv, major, w_lift
  std::vector<std::uint8_t> flags_ref;
  std::vector<float> mirror_ref;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const float r = range.at(x, y);
      const double rx = (x - f.cx) / f.fx, ry = (y - f.cy) / f.fy;
      const bool known = std::isfinite(r) && r > 0.0f;
      const float z = known ? static_cast<float>(r / std::sqrt(rx * rx + ry * ry + 1.0)) : INFINITY;
      const double inv = 1.0 / std::sqrt(rx * rx + ry * ry + 1.0);
      const double dn = rx * inv * f.nx + ry * inv * f.ny + inv * f.nz;
      const bool plane = known && dn < 0.0 && std::fabs(f.h + z / inv * dn) <= f.tol;
      z_ref[i] = z, zo_ref[i] = plane ? INFINITY : z;
      const bool down = std::isfinite(z) && dn < 0.0;
      fl_ref[i] = (down ? detail::kWetDown : 0) | (plane ? detail::kWetOnPlane : 0);
      if (!down) continue;
      const double dx = rx * inv, dy = ry * inv, dz = inv, r0 = z / inv;
      const double Px = r0 * dx, Py = r0 * dy, Pz = r0 * dz;
      const double Dx = dx - 2.0 * dn * f.nx, Dy = dy - 2.0 * dn * f.ny;
      double Dz = dz - 2.0 * dn * f.nz;
      if (std::fabs(Dz) < 1e-9) Dz = Dz < 0.0 ? -1e-9 : 1e-9;
      const double bu = f.fx * Dx + f.cx * Dz, bv = f.fy * Dy + f.cy * Dz;
      const double cu = f.fx * Px + f.cx * Pz - bu * Pz / Dz, cv = f.fy * Py + f.cy * Pz - bv * Pz / Dz;
      const double major = std::max(std::fabs(cu), std::fabs(cv));
      std::uint8_t fl = Dz > 0.0 ? detail::WetMarchRays::dz_positive : 0;
      double w_lift = 0.0;
      const double t_lift = (f.tol - (f.h + r0 * dn)) / -dn;
      const double z_lift = Pz + std::max(t_lift, 0.0) * Dz;
      if (t_lift <= 0.0)
        fl |= detail::WetMarchRays::lifted;
      else if (z_lift > 0.0)
        fl |= detail::WetMarchRays::can_lift, w_lift = 1.0 / z_lift;
      ray_ref.push_back({1.0 / Pz, (Dz > 0.0 ? -1.0 : 1.0) * kWetMarchStepPx / std::max(major, 1e-30), bu / Dz, bv / Dz,
                         cu, cv, major, w_lift});
      flags_ref.push_back(fl);
      mirror_ref.push_back(static_cast<float>(o.mirror(-dn)));
      px.push_back(x), py.push_back(y), pz.push_back(z);
    }
  ASSERT_GT(px.size(), 600u);
  std::size_t on_plane = 0, lifted = 0, can_lift = 0;
  for (const auto fl : fl_ref) on_plane += (fl & detail::kWetOnPlane) != 0;
  for (const auto fl : flags_ref)
    lifted += (fl & detail::WetMarchRays::lifted) != 0, can_lift += (fl & detail::WetMarchRays::can_lift) != 0;
  ASSERT_GT(on_plane, 200u);  // every branch, and often
  ASSERT_GT(lifted, 100u);
  ASSERT_GT(can_lift, 100u);
  std::vector<double> rxs(W);
  for (int x = 0; x < W; ++x) rxs[x] = (x - f.cx) / f.fx;
  const auto same = [](const auto& a, const auto& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
  };
  for (const std::int64_t t : simd::targets()) {
    SCOPED_TRACE(simd::target_name(t));
    simd::force_target(t);
    std::vector<float> z(W * H), zo(W * H);
    std::vector<std::uint8_t> fl(W * H);
    for (int y = 0; y < H; ++y) {
      const std::size_t o0 = static_cast<std::size_t>(y) * W;
      detail::wet_depth_row(f, rxs.data(), (y - f.cy) / f.fy, &range.at(0, y), W, z.data() + o0, zo.data() + o0,
                            fl.data() + o0);
    }
    EXPECT_TRUE(same(z, z_ref));
    EXPECT_TRUE(same(zo, zo_ref));
    EXPECT_EQ(fl, fl_ref);
    detail::WetMarchRays rays;
    std::vector<float> mirror(px.size());
    detail::wet_setup_rays(f, px.data(), py.data(), pz.data(), px.size(), rays, mirror.data());
    ASSERT_EQ(rays.size(), px.size());
    const std::vector<double>* got[8] = {&rays.w0, &rays.dw, &rays.uinf, &rays.vinf, &rays.cu, &rays.cv, &rays.major, &rays.w_lift};
    for (int k = 0; k < 8; ++k) {
      std::vector<double> want(px.size());
      for (std::size_t i = 0; i < px.size(); ++i) want[i] = ray_ref[i][k];
      EXPECT_TRUE(same(*got[k], want)) << "field " << k;
    }
    EXPECT_EQ(rays.flags, flags_ref);
    EXPECT_TRUE(same(mirror, mirror_ref));
    // blocks (no lift): the same rays without the lift's flags and w_lift
    detail::WetPixelFrame fb = f;
    fb.lift = false;
    detail::wet_setup_rays(fb, px.data(), py.data(), pz.data(), px.size(), rays, mirror.data());
    std::vector<std::uint8_t> dz_only(flags_ref);
    for (auto& q : dz_only) q &= detail::WetMarchRays::dz_positive;
    EXPECT_EQ(rays.flags, dz_only);
    EXPECT_TRUE(std::all_of(rays.w_lift.begin(), rays.w_lift.end(), [](double v) { return v == 0.0; }));
    for (std::size_t i = 0; i < px.size(); ++i) ASSERT_EQ(rays.cu[i], ray_ref[i][4]) << i;
  }
  simd::force_target(0);
}

namespace {

std::vector<float> lidar_scan() {
  std::vector<float> v;
  for (int i = 0; i < 400; ++i) {  // ground points at 1.73 m below, ranges 2 m .. 60 m, all around
    const double r = 2.0 + 0.145 * i, az = 0.37 * i;
    const double g = std::sqrt(std::max(0.0, r * r - 1.73 * 1.73));
    v.insert(v.end(), {static_cast<float>(g * std::cos(az)), static_cast<float>(g * std::sin(az)), -1.73f + 0.05f * ((i % 5) - 2) / 2.0f,
                       static_cast<float>(0.05 + 0.002 * (i % 100))});
  }
  for (int i = 0; i < 100; ++i)  // off the ground: walls and cars
    v.insert(v.end(), {static_cast<float>(5.0 + i), 2.0f, static_cast<float>(-1.0 + 0.02 * i), 0.3f});
  return v;
}

}  // namespace

TEST(WetLidar, FilmZeroIsTheScanByteForByte) {
  const std::vector<float> in = lidar_scan();
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::vector<std::uint8_t> labels(n);
  LidarWetParams p;
  p.film = film(0.0);
  const LidarWetStats st = lidar_wet(in.data(), out.data(), n, p, labels.data());
  EXPECT_EQ(st.lost, 0u);
  EXPECT_EQ(std::memcmp(in.data(), out.data(), in.size() * sizeof(float)), 0);
}

TEST(WetLidar, GroundFollowsTheClosedFormOffGroundUnchanged) {
  // Ground points: i (1 - R_F)^2 / (n^2 (1 - a r_i)) at cos theta = -z/r, the Fresnel of the
  // angle form and r_e of the midpoint rule (1e-6 relative: float storage, 6e-8).
  const std::vector<float> in = lidar_scan();
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::vector<std::uint8_t> labels(n);
  LidarWetParams p;
  p.film = film(3.0, 0.2);
  p.scan.noise_floor = 1e-12;  // nothing lost: every point's closed form is checked
  const LidarWetStats st = lidar_wet(in.data(), out.data(), n, p, labels.data());
  ASSERT_EQ(st.lost, 0u);
  const double nn = 1.333, re = r_e_midpoint(nn), ri = 1.0 - (1.0 - re) / (nn * nn);
  std::size_t ground = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = &in[4 * i];
    const float* o = &out[4 * i];
    EXPECT_EQ(std::memcmp(q, o, 3 * sizeof(float)), 0);
    const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    if (std::fabs(q[2] + 1.73) <= 0.2) {
      ++ground;
      EXPECT_EQ(labels[i], 1);
      const double t = 1.0 - fresnel_angles(std::acos(-q[2] / r), nn);
      const double expect = q[3] * t * t / (nn * nn * (1.0 - 0.2 * ri));
      EXPECT_NEAR(o[3], expect, 1e-6 * expect) << i;
    } else {
      EXPECT_EQ(labels[i], 0);
      EXPECT_EQ(std::memcmp(q, o, 4 * sizeof(float)), 0) << i;
    }
  }
  EXPECT_EQ(ground, 400u);
  EXPECT_EQ(st.ground, 400u);
}

TEST(WetLidar, WeakGroundReturnsAreLostAndLabelled) {
  const std::vector<float> in = lidar_scan();
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::vector<std::uint8_t> labels(n);
  LidarWetParams p;
  p.film = film(3.0);
  p.scan.noise_floor = 2e-4;
  const LidarWetStats st = lidar_wet(in.data(), out.data(), n, p, labels.data());
  EXPECT_GT(st.lost, 10u);
  EXPECT_LT(st.lost, 400u);
  std::size_t k = 0, lost = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (labels[i] == 2) {
      ++lost;
      EXPECT_LE(std::fabs(in[4 * i + 2] + 1.73f), 0.2f);  // only ground points are lost
      continue;
    }
    EXPECT_EQ(std::memcmp(&in[4 * i], &out[4 * k], 3 * sizeof(float)), 0);  // the kept, in input order
    ++k;
  }
  EXPECT_EQ(lost, st.lost);
  std::vector<float> bad = in;
  bad[3] = -1.0f;
  EXPECT_THROW(lidar_wet(bad.data(), out.data(), n, p), Error);
}
