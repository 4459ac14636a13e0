// brume — the sun's position from date, time and place: the NOAA Global
// Monitoring Laboratory's solar calculator (its spreadsheet's formulas, after
// Meeus, "Astronomical Algorithms", 2nd ed., ch. 25 (low accuracy, with the
// nutation and aberration corrections of the apparent longitude) and ch. 28
// (equation of time)); accuracy about 0.01 deg for 1800-2100 (UT1 taken as
// UTC: the sun moves 0.004 deg in the 0.9 s they may differ).
// Refraction: NOAA's piecewise approximation of the apparent-elevation
// correction at sea level, scaled by the standard-atmosphere pressure ratio
// e^{-h/8434 m} at the observer's altitude (refraction is proportional to the
// air's density). The sky model uses the TRUE elevation (the model is in the
// geometric frame); the apparent one is reported.
#include <cctype>
#include <cmath>
#include <cstdio>
#include <string>

#include "brume/error.hpp"
#include "core/math_constants.hpp"
#include "brume/sky.hpp"

namespace brume {

namespace {


double wrap360(double a) {
  double r = std::fmod(a, 360.0);
  return r < 0 ? r + 360.0 : r;
}

// Julian day at 0h UT of a Gregorian calendar date (Meeus eq. 7.1).
double julian_day_0h(int y, int m, int d) {
  if (m <= 2) y -= 1, m += 12;
  const int a = y / 100;
  const int b = 2 - a + a / 4;
  return std::floor(365.25 * (y + 4716)) + std::floor(30.6001 * (m + 1)) + d + b - 1524.5;
}

int days_in_month(int y, int m) {
  static const int dm[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
  return m == 2 && leap ? 29 : dm[m - 1];
}

}  // namespace

double julian_day_of(const std::string& s, const std::string& flag) {
  auto bad = [&](const std::string& why) {
    return Error(flag + " '" + s + "' is not an ISO 8601 instant with a UTC offset (" + why +
                 "); write e.g. 2013-05-27T12:00:00-04:00 or 2013-05-27T16:00Z");
  };
  int y = 0, mo = 0, d = 0, h = 0, mi = 0, n = 0;
  if (std::sscanf(s.c_str(), "%4d-%2d-%2d%n", &y, &mo, &d, &n) != 3 || n != 10) throw bad("date YYYY-MM-DD");
  std::size_t i = 10;
  if (i >= s.size() || (s[i] != 'T' && s[i] != ' ')) throw bad("no time: THH:MM");
  ++i;
  int n2 = 0;
  if (std::sscanf(s.c_str() + i, "%2d:%2d%n", &h, &mi, &n2) != 2 || n2 != 5) throw bad("time HH:MM");
  i += 5;
  double sec = 0.0;
  if (i < s.size() && s[i] == ':') {
    ++i;
    std::size_t j = i;
    while (j < s.size() && (std::isdigit(static_cast<unsigned char>(s[j])) || s[j] == '.')) ++j;
    if (j == i) throw bad("seconds");
    sec = std::stod(s.substr(i, j - i));
    i = j;
  }
  double offset_min = 0.0;
  if (i >= s.size()) throw bad("no UTC offset: a local time is ambiguous; add Z or +hh:mm/-hh:mm");
  if (s[i] == 'Z' && i + 1 == s.size()) {
    offset_min = 0.0;
  } else if (s[i] == '+' || s[i] == '-') {
    int oh = 0, om = 0, n3 = 0;
    if (std::sscanf(s.c_str() + i + 1, "%2d:%2d%n", &oh, &om, &n3) != 2 || n3 != 5 || i + 6 != s.size())
      throw bad("offset +hh:mm");
    if (oh > 14 || om > 59) throw bad("offset beyond +-14:00");
    offset_min = (s[i] == '-' ? -1.0 : 1.0) * (oh * 60 + om);
  } else {
    throw bad("trailing text");
  }
  if (mo < 1 || mo > 12 || d < 1 || d > days_in_month(y, mo) || h > 23 || mi > 59 || sec >= 61.0)
    throw bad("a field is out of range");
  if (y < 1800 || y > 2100) throw bad("the algorithm is stated for years 1800-2100");
  // Local time minus the offset is UT.
  return julian_day_0h(y, mo, d) + (h * 60.0 + mi + sec / 60.0 - offset_min) / 1440.0;
}

SolarPosition solar_position_jd(double jd, double lat, double lon, double altitude_m) {
  if (!(lat >= -90.0 && lat <= 90.0)) throw Error("--latitude " + std::to_string(lat) + " is not in [-90, 90] degrees");
  if (!(lon >= -180.0 && lon <= 180.0))
    throw Error("--longitude " + std::to_string(lon) + " is not in [-180, 180] degrees (east positive)");
  const double jc = (jd - 2451545.0) / 36525.0;
  const double l0 = wrap360(280.46646 + jc * (36000.76983 + jc * 0.0003032));
  const double m = 357.52911 + jc * (35999.05029 - 0.0001537 * jc);
  const double e = 0.016708634 - jc * (0.000042037 + 0.0000001267 * jc);
  const double c = std::sin(m * kDeg) * (1.914602 - jc * (0.004817 + 0.000014 * jc)) +
                   std::sin(2 * m * kDeg) * (0.019993 - 0.000101 * jc) + std::sin(3 * m * kDeg) * 0.000289;
  const double true_long = l0 + c;
  const double omega = 125.04 - 1934.136 * jc;
  const double app_long = true_long - 0.00569 - 0.00478 * std::sin(omega * kDeg);
  const double eps0 = 23.0 + (26.0 + (21.448 - jc * (46.815 + jc * (0.00059 - jc * 0.001813))) / 60.0) / 60.0;
  const double eps = eps0 + 0.00256 * std::cos(omega * kDeg);
  const double decl = std::asin(std::sin(eps * kDeg) * std::sin(app_long * kDeg)) / kDeg;
  const double vy = std::tan(eps / 2 * kDeg) * std::tan(eps / 2 * kDeg);
  const double eot = 4.0 / kDeg *
                     (vy * std::sin(2 * l0 * kDeg) - 2 * e * std::sin(m * kDeg) +
                      4 * e * vy * std::sin(m * kDeg) * std::cos(2 * l0 * kDeg) -
                      0.5 * vy * vy * std::sin(4 * l0 * kDeg) - 1.25 * e * e * std::sin(2 * m * kDeg));
  // Minutes of the UT day, then true solar time at the longitude.
  const double day_frac = (jd + 0.5) - std::floor(jd + 0.5);
  const double tst = std::fmod(day_frac * 1440.0 + eot + 4.0 * lon + 1440.0 * 2, 1440.0);
  const double ha = tst / 4.0 < 0 ? tst / 4.0 + 180.0 : tst / 4.0 - 180.0;
  const double cz = std::sin(lat * kDeg) * std::sin(decl * kDeg) +
                    std::cos(lat * kDeg) * std::cos(decl * kDeg) * std::cos(ha * kDeg);
  const double zen = std::acos(std::max(-1.0, std::min(1.0, cz))) / kDeg;
  double az;
  const double den = std::cos(lat * kDeg) * std::sin(zen * kDeg);
  if (std::fabs(den) < 1e-12) {
    az = lat > 0 ? 180.0 : 0.0;  // the sun at the zenith or an observer at a pole: azimuth undefined
  } else {
    const double ca = std::max(-1.0, std::min(1.0, (std::sin(lat * kDeg) * std::cos(zen * kDeg) - std::sin(decl * kDeg)) / den));
    const double a = std::acos(ca) / kDeg;
    az = ha > 0 ? wrap360(a + 180.0) : wrap360(540.0 - a);
  }
  const double el = 90.0 - zen;
  double refr_s;  // arcseconds, NOAA's approximation at sea level
  const double te = std::tan(el * kDeg);
  if (el > 85.0) refr_s = 0.0;
  else if (el > 5.0) refr_s = 58.1 / te - 0.07 / (te * te * te) + 0.000086 / std::pow(te, 5);
  else if (el > -0.575) refr_s = 1735.0 + el * (-518.2 + el * (103.4 + el * (-12.79 + el * 0.711)));
  else refr_s = -20.772 / te;
  const double pressure_ratio = std::exp(-altitude_m / 8434.0);
  SolarPosition s;
  s.zenith_deg = zen;
  s.elevation_deg = el;
  s.refracted_elevation_deg = el + refr_s / 3600.0 * pressure_ratio;
  s.azimuth_deg = az;
  s.declination_deg = decl;
  s.equation_of_time_min = eot;
  s.julian_day = jd;
  return s;
}

SolarPosition solar_position(const std::string& iso8601, double lat, double lon, double altitude_m) {
  return solar_position_jd(julian_day_of(iso8601), lat, lon, altitude_m);
}

}  // namespace brume
