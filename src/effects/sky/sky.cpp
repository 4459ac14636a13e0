// brume — the Preetham sky: double-precision reference model, projections,
// the renderer (shared float maths, src/effects/sky/sky_math.glsl) and the sun
// found in an image. Equations and conventions: include/brume/sky.hpp.
#include "brume/sky.hpp"

#include <algorithm>
#include <cmath>
#include <omp.h>

#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/pipeline.hpp"
#include "core/text.hpp"
#include "core/math_constants.hpp"
#include "brume_opencv.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

namespace sh = brume::shared;

namespace {



double sky_wrap360(double a) {
  double r = std::fmod(a, 360.0);
  if (r < 0) r += 360.0;
  return r >= 360.0 ? 0.0 : r;
}

}  // namespace

void check_sky_turbidity(double t, const std::string& flag) {
  if (!(t >= kSkyTurbidityMin && t <= kSkyTurbidityMax))
    throw Error(flag + " " + text::g(t) +
                " is outside the sky model's [1.7, 20]: Preetham's fit turns negative below T = 1.65 "
                "(the gradation term 1 + A e^B of the luminance changes sign) and 20 is the top of the "
                "thesis' range; use a turbidity in [1.7, 20]");
}

// ---- double-precision model (the paper's table; independent of the float copy) ----------
PerezCoefficients perez_coefficients(SkyChannel ch, double t) {
  switch (ch) {
    case SkyChannel::Y:
      return {0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771,
              -0.0670 * t + 0.3703};
    case SkyChannel::x:
      return {-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989,
              -0.0033 * t + 0.0452};
    case SkyChannel::y:
    default:
      return {-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537,
              -0.0109 * t + 0.0529};
  }
}

double perez(const PerezCoefficients& k, double theta, double gamma) {
  const double ct = std::max(std::cos(theta), 1e-4);  // the horizon limit, as sky_math.glsl
  const double cg = std::cos(gamma);
  return (1.0 + k.a * std::exp(k.b / ct)) * (1.0 + k.c * std::exp(k.d * gamma) + k.e * cg * cg);
}

SkyZenith sky_zenith(double t, double ts) {
  const double chi = (4.0 / 9.0 - t / 120.0) * (kPi - 2.0 * ts);
  SkyZenith z;
  z.Y_kcd = (4.0453 * t - 4.9710) * std::tan(chi) - 0.2155 * t + 2.4192;
  const double s2 = ts * ts, s3 = s2 * ts;
  z.x = t * t * (0.00166 * s3 - 0.00375 * s2 + 0.00209 * ts) +
        t * (-0.02903 * s3 + 0.06377 * s2 - 0.03202 * ts + 0.00394) +
        (0.11693 * s3 - 0.21196 * s2 + 0.06052 * ts + 0.25886);
  z.y = t * t * (0.00275 * s3 - 0.00610 * s2 + 0.00317 * ts) +
        t * (-0.04214 * s3 + 0.08970 * s2 - 0.04153 * ts + 0.00516) +
        (0.15346 * s3 - 0.26756 * s2 + 0.06670 * ts + 0.26688);
  return z;
}

double sky_relative_luminance(double t, double theta, double gamma, double ts) {
  const PerezCoefficients k = perez_coefficients(SkyChannel::Y, t);
  return perez(k, theta, gamma) / perez(k, 0.0, ts);
}

std::array<double, 3> sky_xyY(double t, double theta, double gamma, double ts) {
  const SkyZenith z = sky_zenith(t, ts);
  auto rel = [&](SkyChannel c) {
    const PerezCoefficients k = perez_coefficients(c, t);
    return perez(k, theta, gamma) / perez(k, 0.0, ts);
  };
  return {z.Y_kcd * rel(SkyChannel::Y), z.x * rel(SkyChannel::x), z.y * rel(SkyChannel::y)};
}

double angle_between(double t1, double p1, double t2, double p2) {
  const double c = std::sin(t1) * std::sin(t2) * std::cos(p1 - p2) + std::cos(t1) * std::cos(t2);
  return std::acos(std::clamp(c, -1.0, 1.0));
}

// ---- projections -----------------------------------------------------------------------
const ParamTable<SkyViewParams>& sky_view_param_table() {
  static const ParamTable<SkyViewParams> t = [] {
    ParamTable<SkyViewParams> d("sky-view");
    d.choice("projection", &SkyViewParams::projection, {"fisheye", "equirectangular", "pinhole"},
             "how the image maps to directions: fisheye (looking up, equidistant), equirectangular "
             "(row 0 at the zenith), pinhole (--fx.. or --fov-x, --yaw --pitch --roll)")
        .real_or_unset("fisheye-radius", &SkyViewParams::fisheye_radius_px, "px", Range::above(0.0),
                       "fisheye: radius of the horizon circle; auto: min(W, H)/2", NAN)
        .real("azimuth-offset", &SkyViewParams::azimuth_offset_deg, "deg", Range::closed(-360.0, 360.0),
              "compass azimuth of the image's up direction (fisheye) or centre column (equirectangular)");
    // The pinhole intrinsics carry the names of `depth convert`'s flags.
    ParamTable<Intrinsics> k("sky-view");
    k.real_or_unset("fx", &Intrinsics::fx, "px", Range::above(0.0), "pinhole focal length in pixels (x)", 0.0)
        .real_or_unset("fy", &Intrinsics::fy, "px", Range::above(0.0), "pinhole focal length (y); auto: --fx", 0.0)
        .real_or_unset("cx", &Intrinsics::cx, "px", Range::any(), "pinhole principal point x; auto: (W-1)/2", NAN)
        .real_or_unset("cy", &Intrinsics::cy, "px", Range::any(), "pinhole principal point y; auto: (H-1)/2", NAN);
    d.nest(&SkyViewParams::k, k)
        .real_or_unset("fov-x", &SkyViewParams::fov_x_deg, "deg", Range::left_open(0.0, 180.0),
                       "pinhole horizontal field of view, edge to edge", NAN)
        .real_or_unset("fov-y", &SkyViewParams::fov_y_deg, "deg", Range::left_open(0.0, 180.0),
                       "pinhole vertical field of view, edge to edge", NAN)
        .nest(&SkyViewParams::lens, lens_param_table("sky-view"))
        // Only the orientation: a sky is at infinity, so the camera's position
        // (height, x, z, a view matrix's translation) would be ignored, and a
        // flag a command would ignore is not offered.
        .nest_except(&SkyViewParams::pose, camera_pose_param_table(),
                     {"camera-height", "camera-x", "camera-z", "view-matrix"});
    return d;
  }();
  return t;
}

SkyGeometry sky_geometry(const SkyViewParams& v, int width, int height) {
  if (width <= 0 || height <= 0)
    throw Error("sky image size " + std::to_string(width) + "x" + std::to_string(height) + " is not allowed; use > 0");
  SkyGeometry g;
  g.width = width, g.height = height;
  if (v.projection == "fisheye") g.projection = Projection::fisheye;
  else if (v.projection == "equirectangular") g.projection = Projection::equirectangular;
  else if (v.projection == "pinhole") g.projection = Projection::pinhole;
  else
    throw Error("--projection '" + v.projection + "' is not a sky projection; use fisheye, equirectangular or pinhole");
  if (!std::isfinite(v.azimuth_offset_deg))
    throw Error("--azimuth-offset " + text::g(v.azimuth_offset_deg) + " is not finite; give degrees");
  g.azimuth_offset_deg = v.azimuth_offset_deg;
  g.cx = (width - 1) / 2.0, g.cy = (height - 1) / 2.0;
  g.radius_px = std::isnan(v.fisheye_radius_px) ? std::min(width, height) / 2.0 : v.fisheye_radius_px;
  if (!(g.radius_px > 0.0))
    throw Error("--fisheye-radius " + text::g(g.radius_px) + " is not allowed; use a radius > 0 px");
  if (g.projection != Projection::fisheye && !std::isnan(v.fisheye_radius_px))
    throw Error("--fisheye-radius is for --projection fisheye, not " + v.projection + "; drop it");
  if (g.projection == Projection::pinhole) {
    if (v.azimuth_offset_deg != 0.0)
      throw Error("--azimuth-offset " + text::g(v.azimuth_offset_deg) +
                  " is not used by --projection pinhole (--yaw gives the compass azimuth of the optical axis); "
                  "use --yaw instead");
    // The depth block's rules (depth_intrinsics): the pixels, else the
    // camera in millimetres; both must agree within 1 %.
    DepthSource cam;
    cam.k = v.k;
    cam.fov_x_deg = v.fov_x_deg, cam.fov_y_deg = v.fov_y_deg;
    cam.lens = v.lens;
    const bool pixels = v.k.fx > 0.0 || v.k.fy > 0.0 || !std::isnan(v.fov_x_deg) || !std::isnan(v.fov_y_deg);
    if (!pixels && !v.lens.given())
      throw Error("--projection pinhole needs the camera: give --fx (and --fy, --cx, --cy) or --fov-x/--fov-y, or "
                  "--focal-length MM --sensor-width MM");
    Intrinsics k = depth_intrinsics(cam, width, height);
    g.camera = make_camera(k, width, height, v.pose, Projection::pinhole);
  } else {
    const bool pinhole_flag = v.k.fx > 0.0 || v.k.fy > 0.0 || !std::isnan(v.k.cx) || !std::isnan(v.k.cy) ||
                              !std::isnan(v.fov_x_deg) || !std::isnan(v.fov_y_deg) || v.lens.given() ||
                              v.pose.yaw_deg != 0.0 ||
                              v.pose.pitch_deg != 0.0 || v.pose.roll_deg != 0.0;
    if (pinhole_flag)
      throw Error("--fx/--fy/--cx/--cy/--fov-x/--fov-y/--focal-length/--sensor-width/--lens-shift/--yaw/--pitch/--roll "
                  "describe a pinhole camera, but "
                  "--projection is " + v.projection + "; drop them, or use --azimuth-offset to turn the image");
  }
  return g;
}

std::optional<SkyDirection> direction_of_pixel(const SkyGeometry& g, double u, double v) {
  switch (g.projection) {
    case Projection::fisheye: {
      const double du = u - g.cx, dv = v - g.cy;
      const double r = std::hypot(du, dv);
      if (r > g.radius_px) return std::nullopt;
      // Seen from below with north up, east is on the left: azimuth grows counter-clockwise.
      const double phi = r > 0.0 ? std::atan2(-du, -dv) / kDeg : 0.0;
      return SkyDirection{90.0 * r / g.radius_px, sky_wrap360(phi + g.azimuth_offset_deg)};
    }
    case Projection::equirectangular: {
      if (v < -0.5 || v > g.height - 0.5) return std::nullopt;
      const double phi = 360.0 * (u + 0.5) / g.width - 180.0 + g.azimuth_offset_deg;
      return SkyDirection{180.0 * (v + 0.5) / g.height, sky_wrap360(phi)};
    }
    case Projection::pinhole:
    default: {
      const Vec3 d = g.camera.world_ray(u, v);  // x east, y up, z south
      const double theta = std::acos(std::clamp(d.y, -1.0, 1.0)) / kDeg;
      return SkyDirection{theta, sky_wrap360(std::atan2(d.x, -d.z) / kDeg)};
    }
  }
}

std::optional<std::array<double, 2>> pixel_of_direction(const SkyGeometry& g, const SkyDirection& d) {
  switch (g.projection) {
    case Projection::fisheye: {
      if (d.zenith_deg > 90.0 || d.zenith_deg < 0.0) return std::nullopt;
      const double r = d.zenith_deg / 90.0 * g.radius_px;
      const double p = (d.azimuth_deg - g.azimuth_offset_deg) * kDeg;
      return std::array<double, 2>{g.cx - r * std::sin(p), g.cy - r * std::cos(p)};
    }
    case Projection::equirectangular: {
      if (d.zenith_deg > 180.0 || d.zenith_deg < 0.0) return std::nullopt;
      // Column: the azimuth relative to the image's centre column, in [-180, 180).
      double a = sky_wrap360(d.azimuth_deg - g.azimuth_offset_deg + 180.0) - 180.0;
      return std::array<double, 2>{(a + 180.0) / 360.0 * g.width - 0.5, d.zenith_deg / 180.0 * g.height - 0.5};
    }
    case Projection::pinhole:
    default: {
      const double t = d.zenith_deg * kDeg, p = d.azimuth_deg * kDeg;
      const Vec3 w{std::sin(t) * std::sin(p), std::cos(t), -std::sin(t) * std::cos(p)};
      const Vec3 cv = cv_from_eye(g.camera.orientation.transposed() * w);
      if (cv.z <= 0.0) return std::nullopt;
      return std::array<double, 2>{g.camera.k.fx * cv.x / cv.z + g.camera.k.cx,
                                   g.camera.k.fy * cv.y / cv.z + g.camera.k.cy};
    }
  }
}

// ---- render -----------------------------------------------------------------------------
Image render_sky(const SkyRenderParams& p, const SkyDirection& sun, const SkyGeometry& g, const Exec& exec) {
  check_sky_turbidity(p.turbidity);
  if (!(sun.zenith_deg >= 0.0 && sun.zenith_deg < 90.0))
    throw Error("the sun's zenith angle " + text::g(sun.zenith_deg) +
                " deg is not above the horizon; the Preetham model has no twilight: use a sun zenith in [0, 90)");
  Image out(g.width, g.height, 3, NAN);
  const float t = static_cast<float>(p.turbidity);
  const float ts = static_cast<float>(sun.zenith_deg * kDeg);
  const float ps = static_cast<float>(sun.azimuth_deg * kDeg);
  // Per-image constants: the coefficients and the zenith normalisations F(0, theta_s).
  float cf[3][5];
  for (int k = 0; k < 5; ++k) {
    cf[0][k] = sh::brume_perez_coef_Y(k, t);
    cf[1][k] = sh::brume_perez_coef_x(k, t);
    cf[2][k] = sh::brume_perez_coef_y(k, t);
  }
  float zen[3] = {sh::brume_sky_zenith_Y(t, ts), sh::brume_sky_zenith_x(t, ts), sh::brume_sky_zenith_y(t, ts)};
  float scale[3];
  for (int c = 0; c < 3; ++c)
    scale[c] = zen[c] / (sh::brume_perez_theta(cf[c][0], cf[c][1], 1.0f) *
                         sh::brume_perez_gamma(cf[c][2], cf[c][3], cf[c][4], ts, std::cos(ts)));
  scale[0] *= static_cast<float>(p.exposure);
  const float sin_ts = std::sin(ts), cos_ts = std::cos(ts);
  // The gamma term of each channel, tabulated once per image (a schedule
  // choice, as the aerial effect's Gamma table): per pixel this replaces an
  // acos and three exp by a sqrt and three lerps (about 2.4x: 3.5x -> 8x the
  // double-reference peer of bench_sky, measured under load). Nodes are
  // uniform in s = sqrt(1 - cos gamma), in which gamma = 2 asin(s / sqrt 2) is
  // smooth up to the sun (in cos gamma it is not: d gamma / d cos gamma is
  // infinite at gamma = 0). The entries are the shared maths' values
  // (brume_perez_gamma) times the normalisation; the linear interpolation
  // error is <= ds^2/8 max|G''| ~ 1e-6 relative with 4096 intervals
  // (tests/test_sky.cpp holds the render to the double reference at 2e-5).
  constexpr int kGammaNodes = 4096;
  const float s_max = std::sqrt(2.0f), ds = s_max / kGammaNodes;
  std::vector<float> gtab(3 * (kGammaNodes + 2));
  for (int j = 0; j <= kGammaNodes + 1; ++j) {
    const float sj = std::min(j * ds, s_max);
    const float gamma = 2.0f * std::asin(std::min(sj / s_max, 1.0f));
    const float cg = 1.0f - sj * sj;
    for (int c = 0; c < 3; ++c)
      gtab[3 * j + c] = scale[c] * sh::brume_perez_gamma(cf[c][2], cf[c][3], cf[c][4], gamma, cg);
  }
  const float cos_disc = static_cast<float>(std::cos(p.sun_disc_radius_deg * kDeg));
  const float sun_Y = static_cast<float>(p.sun_luminance_kcd * p.exposure);
  const bool equirect = g.projection == Projection::equirectangular;
  // Equirectangular: phi depends on the column only, theta on the row only.
  std::vector<float> cos_dphi(equirect ? g.width : 0);
  for (int x = 0; x < static_cast<int>(cos_dphi.size()); ++x)
    cos_dphi[x] = static_cast<float>(std::cos(direction_of_pixel(g, x, 0)->azimuth_deg * kDeg - ps));
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(dynamic, 4)  // sky rows cost, ground rows do not
  for (int y = 0; y < g.height; ++y) {
    float* row = out.row(y);
    float th_row[3] = {0, 0, 0};
    float row_theta = 0, row_sin = 0, row_cos = 0;
    if (equirect) {
      // Everything that depends on theta once per row; rows below the horizon cost nothing.
      row_theta = static_cast<float>(direction_of_pixel(g, 0, y)->zenith_deg * kDeg);
      row_sin = std::sin(row_theta), row_cos = std::cos(row_theta);
      for (int c = 0; c < 3; ++c) th_row[c] = sh::brume_perez_theta(cf[c][0], cf[c][1], row_cos);
      if (row_theta > 0.5f * 3.14159265f) {  // below the horizon: the whole row
        for (int x = 0; x < g.width; ++x)
          if (p.ground) row[3 * x] = (*p.ground)[0], row[3 * x + 1] = (*p.ground)[1], row[3 * x + 2] = (*p.ground)[2];
        continue;
      }
    }
    for (int x = 0; x < g.width; ++x) {
      float* px = row + 3 * x;
      float theta, cdp, st, ct;
      float th[3];
      if (equirect) {
        theta = row_theta, cdp = cos_dphi[x], st = row_sin, ct = row_cos;
        th[0] = th_row[0], th[1] = th_row[1], th[2] = th_row[2];
      } else {
        const std::optional<SkyDirection> d = direction_of_pixel(g, x, y);
        if (!d) continue;  // no direction: NaN
        theta = static_cast<float>(d->zenith_deg * kDeg);
        cdp = static_cast<float>(std::cos(d->azimuth_deg * kDeg - ps));
        st = std::sin(theta), ct = std::cos(theta);
        for (int c = 0; c < 3; ++c) th[c] = sh::brume_perez_theta(cf[c][0], cf[c][1], ct);
      }
      if (theta > 0.5f * 3.14159265f) {
        if (p.ground) px[0] = (*p.ground)[0], px[1] = (*p.ground)[1], px[2] = (*p.ground)[2];
        continue;
      }
      const float cg = sh::brume_sky_cos_gamma(st, ct, sin_ts, cos_ts, cdp);
      const float sg = std::sqrt(std::max(0.0f, 1.0f - cg)) / ds;
      const int j = std::min(static_cast<int>(sg), kGammaNodes);
      const float f = sg - static_cast<float>(j);
      const float* g0 = &gtab[3 * j];
      float v[3];
      for (int c = 0; c < 3; ++c) v[c] = th[c] * (g0[c] + f * (g0[c + 3] - g0[c]));
      float Y = v[0], xx = v[1], yy = v[2];
      if (p.sun_disc && cg >= cos_disc) {
        // The sun's own colour is not modelled: a white (D65, equal-energy in linear sRGB) disc.
        px[0] = px[1] = px[2] = sun_Y;
        continue;
      }
      const float X = xx * Y / yy, Z = (1.0f - xx - yy) * Y / yy;
      px[0] = sh::brume_xyz_to_r(X, Y, Z);
      px[1] = sh::brume_xyz_to_g(X, Y, Z);
      px[2] = sh::brume_xyz_to_b(X, Y, Z);
    }
  }
  return out;
}

// ---- the sun in an image ------------------------------------------------------------------
SunFound find_sun_in_image(DenseImageRef rgb, bool integer_image, const SkyGeometry& g) {
  const int w = rgb.width, h = rgb.height;
  cv::Mat lum(h, w, CV_32F, cv::Scalar(0));
  cv::Mat usable(h, w, CV_8U, cv::Scalar(0));
  std::vector<float> vals;
  vals.reserve(rgb.pixels());
  float lmax = 0.0f, cmax_all = 0.0f;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::optional<SkyDirection> d = direction_of_pixel(g, x, y);
      if (!d || d->zenith_deg > 90.0) continue;
      const float r = rgb.at(x, y, 0), gg = rgb.at(x, y, 1), b = rgb.at(x, y, 2);
      const float l = sh::brume_srgb_to_y(r, gg, b);
      if (!std::isfinite(l)) continue;
      usable.at<unsigned char>(y, x) = 1;
      lum.at<float>(y, x) = integer_image ? std::max({r, gg, b}) : l;
      vals.push_back(lum.at<float>(y, x));
      lmax = std::max(lmax, lum.at<float>(y, x));
      cmax_all = std::max(cmax_all, std::max({r, gg, b}));
    }
  if (vals.empty()) throw Error("--sun auto: the image has no pixels above the horizon in this projection");
  float thr;
  std::string rule;
  if (integer_image) {
    thr = 0.955f;  // sRGB code 250/255: saturated
    rule = "saturated (max channel >= 250/255)";
  } else {
    const std::size_t q = static_cast<std::size_t>(0.999 * (vals.size() - 1));
    std::nth_element(vals.begin(), vals.begin() + q, vals.end());
    thr = std::max(vals[q], 0.5f * lmax);
    rule = "luminance >= max(q_0.999, 0.5 max)";
  }
  cv::Mat mask(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (usable.at<unsigned char>(y, x) && lum.at<float>(y, x) >= thr && lum.at<float>(y, x) > 0.0f)
        mask.at<unsigned char>(y, x) = 255;
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  if (n <= 1)
    throw Error(std::string("--sun auto found no ") + (integer_image ? "saturated" : "bright") +
                " blob above the horizon; give the sun with --sun-zenith/--sun-azimuth or --date --latitude --longitude");
  // The component with the most light (sum of luminance), not the largest: a
  // white cloud may be saturated over a wider area than the sun.
  std::vector<double> sum(n, 0.0), su(n, 0.0), sv(n, 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = labels.at<int>(y, x);
      if (l <= 0) continue;
      const double wv = integer_image ? 1.0 : lum.at<float>(y, x);
      sum[l] += wv, su[l] += wv * x, sv[l] += wv * y;
    }
  int best = 1;
  for (int l = 2; l < n; ++l)
    if (sum[l] > sum[best]) best = l;
  cv::Mat comp = (labels == best);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(comp, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  std::size_t ci = 0;
  for (std::size_t i = 1; i < contours.size(); ++i)
    if (contours[i].size() > contours[ci].size()) ci = i;
  double u, v;
  std::string method;
  if (!contours.empty() && contours[ci].size() >= 6) {
    const cv::RotatedRect e = cv::fitEllipse(contours[ci]);
    u = e.center.x, v = e.center.y;
    method = "fitEllipse";
  } else {
    u = su[best] / sum[best], v = sv[best] / sum[best];
    method = "centroid";
  }
  const std::optional<SkyDirection> d = direction_of_pixel(g, u, v);
  if (!d) throw Error("--sun auto: the blob's centre has no direction in this projection");
  SunFound f;
  f.direction = *d;
  f.source = "auto";
  f.record = {{"pixel", {u, v}},
              {"method", method},
              {"blob_area_px", stats.at<int>(best, cv::CC_STAT_AREA)},
              {"threshold", thr},
              {"rule", rule}};
  return f;
}

const ParamTable<SunParams>& sun_param_table() {
  static const ParamTable<SunParams> t = [] {
    ParamTable<SunParams> d("sun");
    d.choice("sun", &SunParams::sun, {"given", "auto"},
             "given: --sun-zenith/--sun-azimuth or --date --latitude --longitude; auto: the brightest blob of the image")
        .real_or_unset("sun-zenith", &SunParams::zenith_deg, "deg", Range::closed(0.0, 180.0),
                       "the sun's zenith angle (the model needs < 90)", NAN, "none")
        .real_or_unset("sun-azimuth", &SunParams::azimuth_deg, "deg", Range::closed(-360.0, 720.0),
                       "the sun's compass azimuth (north 0, east 90)", NAN, "none")
        .text("date", &SunParams::date, "ISO 8601 instant with UTC offset (2013-05-27T12:00:00-04:00) for the NOAA sun position")
        .real_or_unset("latitude", &SunParams::latitude_deg, "deg", Range::closed(-90.0, 90.0), "north positive", NAN, "none")
        .real_or_unset("longitude", &SunParams::longitude_deg, "deg", Range::closed(-180.0, 180.0), "east positive", NAN,
                       "none")
        .real("altitude", &SunParams::altitude_m, "m", Range::closed(-500.0, 9000.0),
              "observer altitude (scales the refraction of the reported apparent elevation only)");
    return d;
  }();
  return t;
}

SunFound resolve_sun(const SunParams& p, const DenseImageRef* rgb, bool integer_image, const SkyGeometry* g) {
  const bool given = !std::isnan(p.zenith_deg) || !std::isnan(p.azimuth_deg);
  const bool eph = !p.date.empty() || !std::isnan(p.latitude_deg) || !std::isnan(p.longitude_deg);
  SunFound f;
  if (p.sun == "auto") {
    if (given || eph)
      throw Error("--sun auto finds the sun in the image, but --sun-zenith/--sun-azimuth or --date/--latitude/"
                  "--longitude were given too; use one way");
    if (!rgb || !g) throw Error("--sun auto needs an image (brume sky fit); give --sun-zenith and --sun-azimuth");
    f = find_sun_in_image(*rgb, integer_image, *g);
  } else if (given && eph) {
    throw Error("the sun is given twice (--sun-zenith/--sun-azimuth and --date/--latitude/--longitude); use one way");
  } else if (eph) {
    if (p.date.empty() || std::isnan(p.latitude_deg) || std::isnan(p.longitude_deg))
      throw Error("the sun's ephemeris needs all of --date (ISO 8601 with UTC offset), --latitude and --longitude");
    const SolarPosition s = solar_position(p.date, p.latitude_deg, p.longitude_deg, p.altitude_m);
    f.direction = {s.zenith_deg, s.azimuth_deg};
    f.source = "ephemeris";
    f.record = {{"algorithm", "NOAA (Meeus)"},
                {"date", p.date},
                {"latitude_deg", p.latitude_deg},
                {"longitude_deg", p.longitude_deg},
                {"altitude_m", p.altitude_m},
                {"true_elevation_deg", s.elevation_deg},
                {"refracted_elevation_deg", s.refracted_elevation_deg},
                {"julian_day", s.julian_day},
                {"note", "the model uses the true (unrefracted) elevation"}};
  } else if (given) {
    if (std::isnan(p.zenith_deg) || std::isnan(p.azimuth_deg))
      throw Error("the sun needs both --sun-zenith and --sun-azimuth (degrees)");
    f.direction = {p.zenith_deg, sky_wrap360(p.azimuth_deg)};
    f.source = "given";
  } else {
    throw Error("where is the sun? give --sun-zenith DEG --sun-azimuth DEG, or --date --latitude --longitude"
                ", or --sun auto (brume sky fit)");
  }
  if (!(f.direction.zenith_deg < 90.0))
    throw Error("the sun (" + f.source + ") is at zenith angle " + text::g(f.direction.zenith_deg) +
                " deg, not above the horizon; the Preetham model has no twilight: use a daytime sky (sun zenith < 90)");
  return f;
}

}  // namespace brume
