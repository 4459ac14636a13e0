// brume — the Preetham sky and the turbidity of a photographed sky
// (Morales 2014 ch. 2; Preetham, Shirley, Smits 1999; Perez, Seals, Michalsky 1993).
//
// The model. For a view direction at zenith angle theta and angle gamma from
// the sun (zenith angle theta_s), each of the luminance Y and the
// chromaticities x, y is
//   value(theta, gamma) = value_zenith F(theta, gamma) / F(0, theta_s)             (Morales eq. 1.7)
//   F(theta, gamma) = (1 + A e^{B / cos theta}) (1 + C e^{D gamma} + E cos^2 gamma)  (Perez 1993)
// with A..E linear in the turbidity T (Preetham A.2; Morales eq. 1.8 for Y),
// the zenith luminance Y_z [kcd/m^2] = (4.0453T - 4.9710) tan chi - 0.2155T + 2.4192,
// chi = (4/9 - T/120)(pi - 2 theta_s), and the zenith chromaticity cubic in
// theta_s and quadratic in T; the tables are in src/effects/sky/sky_math.glsl.
// Then X = x Y / y, Z = (1 - x - y) Y / y, and linear sRGB = M^-1 XYZ
// (IEC 61966-2-1, the matrix the aerial effect uses: src/effects/aerial/aerial_math.glsl).
// Rendered values are in kcd/m^2 (Y of linear sRGB = Y of XYZ), times --exposure.
//
// Domain: T in [1.7, 20]. Preetham's fit turns negative below T ~ 1.65 --
// the gradation term 1 + A e^B of Y is 1 + (0.1787T - 1.4630) e^{0.4275 - 0.3554T},
// which is 0 at T = 1.649 -- so the zenith normalisation F(0, theta_s) changes
// sign and the sky is meaningless; 20 is the top of the thesis' range (and of
// the aerial effect's). The sun must be above the horizon (theta_s < 90 deg):
// the model has no twilight.
//
// Directions: theta is the zenith angle, phi the COMPASS azimuth (north 0,
// east 90 deg, clockwise seen from above), both in degrees at the interface.
// Projections (one function each way, `direction_of_pixel` / `pixel_of_direction`):
//  * fisheye (looking up, equidistant): centre ((W-1)/2, (H-1)/2), horizon on
//    the circle of radius min(W, H)/2 (or --fisheye-radius), theta = 90 r/radius,
//    phi = atan2(-(u - cx), -(v - cy)) + --azimuth-offset: north up, east on
//    the LEFT (a camera looking up), azimuth increasing counter-clockwise in
//    the image; outside the circle there is no direction.
//  * equirectangular: phi = 360 (u + 0.5)/W - 180 + --azimuth-offset
//    (increasing to the right seen from inside), theta = 180 (v + 0.5)/H
//    (row 0 at the zenith), as Poly Haven's panoramas.
//  * pinhole: the common camera (brume/camera.hpp) with --fx.. or --fov-x/--fov-y
//    and --yaw --pitch --roll; --azimuth-offset must stay 0 (--yaw says it).
//
// Turbidity from a photo (Morales eq. 2.1, with a fitted scale): N sky samples
// i with measured luminance L_i (Y of the linear image) and model
// m_i(T) = F_Y(theta_i, gamma_i) / F_Y(0, theta_s); residuals in log space
//   r_i(T) = log L_i - log k(T) - log m_i(T),  log k(T) = mean_i (log L_i - log m_i(T))
// (the scale k that minimises sum r_i^2 for that T, closed form), so no single
// reference pixel -- which may be a cloud -- sets the normalisation, and the
// bright circumsolar sky does not outweigh the rest. T minimises sum r_i^2 by
// Eigen's Levenberg-Marquardt over T = 1.7 + 18.3 / (1 + e^{-p}) (bounded by
// reparametrisation), started from the best of a 48-point grid in T; RANSAC
// (random 4-sample hypotheses, inliers |r_i| < --inlier-threshold) rejects
// clouds, and the whole sampling is repeated (--repeats) for the spread.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/depth.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"

namespace brume {

constexpr double kSkyTurbidityMin = 1.7;   // Preetham's fit turns negative below 1.65 (above)
constexpr double kSkyTurbidityMax = 20.0;  // the thesis' range
// Throws brume::Error naming `flag`, T, [1.7, 20] and why, when T is outside.
void check_sky_turbidity(double t, const std::string& flag = "--turbidity");

// ---- the model in double precision (the reference; the renderer uses the
// ---- float shared maths of src/effects/sky/sky_math.glsl and is tested against it)
struct PerezCoefficients {
  double a = 0, b = 0, c = 0, d = 0, e = 0;
};
enum class SkyChannel { Y, x, y };
PerezCoefficients perez_coefficients(SkyChannel ch, double turbidity);
// F(theta, gamma), angles in radians.
double perez(const PerezCoefficients& k, double theta_rad, double gamma_rad);
struct SkyZenith {
  double Y_kcd = 0;  // [kcd/m^2] zenith luminance
  double x = 0, y = 0;  // CIE 1931 chromaticity
};
SkyZenith sky_zenith(double turbidity, double theta_s_rad);
// Y(theta, gamma) / Y_z = F_Y(theta, gamma) / F_Y(0, theta_s).
double sky_relative_luminance(double turbidity, double theta_rad, double gamma_rad, double theta_s_rad);
// Y [kcd/m^2], x, y of the sky in one direction.
std::array<double, 3> sky_xyY(double turbidity, double theta_rad, double gamma_rad, double theta_s_rad);
// Angle between two directions given as (zenith angle, azimuth), radians.
double angle_between(double theta1, double phi1, double theta2, double phi2);

// ---- directions and projections -----------------------------------------------------
struct SkyDirection {
  double zenith_deg = 0;   // theta: 0 zenith, 90 horizon, > 90 below
  double azimuth_deg = 0;  // phi: compass azimuth, [0, 360)
};

// How an image maps to directions (the flags; resolved per image size by sky_geometry).
struct SkyViewParams {
  std::string projection = "equirectangular";  // --projection fisheye | equirectangular | pinhole
  double fisheye_radius_px = NAN;   // [px] --fisheye-radius: horizon circle radius; NaN: min(W, H)/2
  double azimuth_offset_deg = 0.0;  // [deg] --azimuth-offset: compass azimuth of the image's up
                                    //       direction (fisheye) or of its centre column (equirect)
  Intrinsics k{0.0, 0.0, NAN, NAN}; // [px] pinhole --fx --fy --cx --cy (0/NaN: unset)
  double fov_x_deg = NAN, fov_y_deg = NAN;  // [deg] pinhole --fov-x --fov-y
  LensCamera lens;                  // pinhole in millimetres: --focal-length, --sensor-width, ... (brume/depth.hpp)
  CameraPose pose;                  // pinhole --yaw --pitch --roll
};
const ParamTable<SkyViewParams>& sky_view_param_table();

struct SkyGeometry {
  Projection projection = Projection::equirectangular;
  int width = 0, height = 0;
  double cx = 0, cy = 0, radius_px = 0;  // fisheye
  double azimuth_offset_deg = 0;
  Camera camera;                          // pinhole
};
// Validates the view for a width x height image (errors name the flags).
SkyGeometry sky_geometry(const SkyViewParams& v, int width, int height);
// The direction seen at pixel (u, v) (pixel centres at integers); nullopt
// where the projection has none (outside the fisheye circle, or beyond the
// equirectangular rows). Directions below the horizon are returned.
std::optional<SkyDirection> direction_of_pixel(const SkyGeometry& g, double u, double v);
// The (fractional) pixel where a direction is seen; nullopt where it is not
// (fisheye: below the horizon; pinhole: behind the camera). May lie outside the image.
std::optional<std::array<double, 2>> pixel_of_direction(const SkyGeometry& g, const SkyDirection& d);

// ---- the sun ------------------------------------------------------------------------
// NOAA solar position (the NOAA Global Monitoring Laboratory's spreadsheet
// algorithm after Meeus, "Astronomical Algorithms" ch. 25, 28; stated
// accuracy about 0.01 deg for 1800-2100, UT1 taken as UTC).
struct SolarPosition {
  double zenith_deg = 0;              // true (geometric) zenith angle: the model uses this one
  double elevation_deg = 0;           // 90 - zenith
  double refracted_elevation_deg = 0; // apparent, NOAA's refraction scaled by the pressure at the altitude
  double azimuth_deg = 0;             // compass, [0, 360)
  double declination_deg = 0;
  double equation_of_time_min = 0;
  double julian_day = 0;              // of the instant (UT)
};
// `iso8601` is "YYYY-MM-DDThh:mm[:ss[.fff]]" with a UTC offset "Z" or
// "+hh:mm"/"-hh:mm" (a local time without one is refused: it is ambiguous).
// Latitude [-90, 90] north positive, longitude [-180, 180] east positive,
// altitude [m] only scales the refraction (standard atmosphere, scale height 8434 m).
SolarPosition solar_position(const std::string& iso8601, double latitude_deg, double longitude_deg,
                             double altitude_m = 0.0);
// The same at a Julian day (UT).
SolarPosition solar_position_jd(double julian_day, double latitude_deg, double longitude_deg, double altitude_m = 0.0);
// Julian day (UT) of an ISO 8601 instant with offset; throws naming `flag`.
double julian_day_of(const std::string& iso8601, const std::string& flag = "--date");

// Where the sun is: given, auto (from the image) or ephemeris (date and place).
struct SunParams {
  std::string sun = "given";      // --sun given | auto
  double zenith_deg = NAN;        // [deg] --sun-zenith [0, 90)
  double azimuth_deg = NAN;       // [deg] --sun-azimuth, compass, any finite (normalised)
  std::string date;               // --date ISO 8601 with UTC offset
  double latitude_deg = NAN;      // [deg] --latitude [-90, 90]
  double longitude_deg = NAN;     // [deg] --longitude [-180, 180]
  double altitude_m = 0.0;        // [m] --altitude [-500, 9000] (refraction only)
};
const ParamTable<SunParams>& sun_param_table();

struct SunFound {
  SkyDirection direction;
  std::string source;      // given | auto | ephemeris
  nlohmann::json record;   // how it was found
};
// Auto-detection on a linear image: the brightest blob -- saturated pixels
// (max channel >= 0.955, sRGB 250/255) of an integer image, or, in a float
// (HDR) image, luminance >= max(q_0.999, 0.5 max) -- by OpenCV's
// connectedComponentsWithStats (8-connected), the component with the largest
// summed luminance; its centre from cv::fitEllipse on its outer contour, or
// its luminance-weighted centroid when the contour has < 6 points (a sun one
// or two pixels wide); then through the projection.
SunFound find_sun_in_image(DenseImageRef rgb, bool integer_image, const SkyGeometry& g);
// Resolve the sun from the flags (image may be null for render: auto refused).
SunFound resolve_sun(const SunParams& p, const DenseImageRef* rgb, bool integer_image, const SkyGeometry* g);

// ---- brume sky render ---------------------------------------------------------------
struct SkyRenderParams {
  double turbidity = 3.0;            // [1] --turbidity [1.7, 20]
  SunParams sun;
  SkyViewParams view;
  int width = 1024, height = 512;    // [px] --width --height
  std::optional<Rgb> ground;         // --ground R,G,B linear (>= 0) below the horizon; unset: NaN
  bool sun_disc = false;             // --sun-disc: draw the sun's disc (the model has none)
  double sun_disc_radius_deg = 0.2666;  // [deg] --sun-disc-radius (0, 10]; the sun's mean angular radius
  double sun_luminance_kcd = 1.6e6;     // [kcd/m^2] --sun-luminance of the disc (the sun: ~1.6e9 cd/m^2)
  double exposure = 1.0;             // [1] --exposure: multiplies every value, > 0
};
const ParamTable<SkyRenderParams>& sky_render_param_table();
// The sky in linear sRGB [kcd/m^2 x exposure]; NaN (or ground) where there is
// no sky. The sun direction is resolved (given or ephemeris).
Image render_sky(const SkyRenderParams& p, const SkyDirection& sun, const SkyGeometry& g, const Exec& exec = {});

// In memory (the Python module's brume.sky.render): checks, the sun, the
// backend (Exec), the image and the record's "sky" and "execution".
struct SkyRenderRun {
  Image rgb;
  nlohmann::json record;
};
SkyRenderRun run_sky_render(const SkyRenderParams& p, const Exec& exec = {});

// ---- brume sky fit ------------------------------------------------------------------
struct SkyFitOptions {
  int samples = 100;               // [1] --samples [10, 100000]
  std::uint64_t seed = 1;          // --seed
  int repeats = 8;                 // [1] --repeats [1, 100]: independent samplings for the spread
  int ransac_iterations = 64;      // [1] --ransac-iterations [1, 10000]
  double inlier_threshold = 0.1;   // [1] --inlier-threshold: |log residual| of an inlier, (0, 2]
  double sun_exclusion_deg = 5.0;  // [deg] --sun-exclusion: samples at least this far from the sun, [0, 90)
  double max_zenith_deg = 87.0;    // [deg] --max-zenith: samples above this zenith angle, (0, 90]
};

struct SkySample {
  SkyDirection direction;
  double u = 0, v = 0;       // pixel
  double measured = 0;       // Y of the linear image (relative)
  double model = 0;          // k F_Y(theta, gamma)/F_Y(0, theta_s) at the fitted T (same units)
  bool inlier = false;
};
struct SkyFitResult {
  double turbidity = NAN;
  double turbidity_spread = NAN;  // standard deviation over the repeats
  double scale = NAN;             // k: measured / relative model luminance
  double inlier_fraction = 0;
  double residual = NAN;          // RMS |log residual| of the inliers
  bool reliable = false;
  std::vector<std::string> reasons;  // why not reliable
  std::size_t candidates = 0;     // usable sky pixels
  std::vector<double> repeat_turbidities;
  std::vector<SkySample> samples;  // of the median repeat
};
// Fit T to measured luminances at known directions (the core; used by the
// image fit and by measured sky data such as Kider et al.'s 81 directions).
// Throws brume::Error when there are fewer than 10 usable samples.
SkyFitResult fit_turbidity(const std::vector<SkySample>& candidates, const SkyDirection& sun, const SkyFitOptions& o);
// Fit on an image (linear RGB): candidates are pixels with a direction above
// the horizon within max_zenith, >= sun_exclusion from the sun, mask > 0.5
// (when given), finite positive luminance and not saturated (integer images).
SkyFitResult fit_sky_image(DenseImageRef rgb, bool integer_image, const SkyGeometry& g, const SkyDirection& sun,
                           const Image* mask, const SkyFitOptions& o);
nlohmann::json sky_fit_json(const SkyFitResult& r, const SunFound& sun);

// The fit options' flags (--samples, --seed, --repeats, --ransac-iterations,
// --inlier-threshold, --sun-exclusion, --max-zenith).
const ParamTable<SkyFitOptions>& sky_fit_param_table();

// `brume sky fit` on an image file without writing anything: read (integer
// images linearised by `transfer`), the optional mask (> half scale = usable
// sky), the view, the sun, the fit. `flags` is the prefix of the caller's flag
// names in messages ("--" for sky fit, "--sky-" for aerial --turbidity auto).
struct SkyImageFit {
  nlohmann::json fit;            // sky_fit_json(...)
  nlohmann::json image_record;   // file_record of the image
  nlohmann::json mask_record;    // of the mask; null when none
  double fit_ms = 0.0;
};
SkyImageFit fit_sky_image_file(const std::string& image, const TransferFunction& transfer, const std::string& mask,
                               const SkyViewParams& view, const SunParams& sun, const SkyFitOptions& fit,
                               const std::string& flags = "--", const std::string& layer = "");

// The same fit on pixels in memory (linear RGB; `integer_image`: they came
// from 8/16-bit values, so saturation is detectable; `mask`: 1 = usable sky,
// binarised, or null). Fills fit and fit_ms. Errors of the fit itself are a
// SkyFitError (the file form prefixes them with the image's flag and name).
class SkyFitError : public Error {
 public:
  using Error::Error;
};
SkyImageFit fit_sky_data(DenseImageRef rgb, bool integer_image, const Image* mask, const SkyViewParams& view,
                         const SunParams& sun, const SkyFitOptions& fit);

// Turbidity from a `brume sky fit` JSON (for `brume aerial --turbidity-from`):
// throws naming `flag` when the file is unreadable, has no number, or the fit
// is flagged unreliable.
double turbidity_from_fit_json(const std::string& path, const std::string& flag = "--turbidity-from");

}  // namespace brume
