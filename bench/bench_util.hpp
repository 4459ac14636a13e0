// brume benchmarks — the one timing convention (STYLE.md #13): one warm-up,
// then the median and the spread (min..max) of `runs` timed runs; and the
// machine's name for the report.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace brume::bench {

struct Spread {
  double median, lo, hi;  // milliseconds
};

// The median (the upper one of an even count) and the range of v, not empty.
inline Spread spread(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return {v[v.size() / 2], v.front(), v.back()};
}

inline Spread time_ms(const std::function<void()>& fn, int runs) {
  fn();  // warm-up
  std::vector<double> t;
  for (int i = 0; i < runs; ++i) {
    const auto a = std::chrono::steady_clock::now();
    fn();
    t.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
  }
  return spread(std::move(t));
}

// The CPU's model name with its family and model numbers: virtual hosts
// often report a bare "AMD EPYC" for different generations (family 25 is
// Zen 3/4, 26 Zen 5), whose speed ratios differ.
inline std::string cpu_name() {
  std::ifstream f("/proc/cpuinfo");
  std::string line, name = "unknown CPU", family, model;
  auto value = [&] {
    const auto c = line.find(':');
    return c == std::string::npos ? std::string() : line.substr(c + 2);
  };
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) name = value();
    else if (line.rfind("cpu family", 0) == 0 && family.empty()) family = value();
    else if (line.rfind("model\t", 0) == 0 && model.empty()) model = value();
    if (line.empty() && name != "unknown CPU") break;  // the first processor's block
  }
  if (!family.empty() && !model.empty()) name += " (family " + family + ", model " + model + ")";
  return name;
}

// The host's load averages over 1, 5 and 15 minutes (/proc/loadavg), for the report.
inline std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

// A LiDAR-like scan of n points (x, y, z, intensity; float32 each): uniform
// azimuth, elevations in [-0.36, 0.09] rad, ranges 3..80 m (denser near),
// intensities uniform in [0, 1); the same for the same n.
inline std::vector<float> synthetic_scan(std::size_t n) {
  std::mt19937 g(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> v(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double az = 6.283185307179586 * u(g), el = (u(g) - 0.8) * 0.45, r = 3.0 + 77.0 * u(g) * u(g);
    v[4 * i] = static_cast<float>(r * std::cos(el) * std::cos(az));
    v[4 * i + 1] = static_cast<float>(r * std::cos(el) * std::sin(az));
    v[4 * i + 2] = static_cast<float>(r * std::sin(el));
    v[4 * i + 3] = static_cast<float>(u(g));
  }
  return v;
}

}  // namespace brume::bench
