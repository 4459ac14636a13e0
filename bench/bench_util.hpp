// brume benchmarks — the one timing convention (STYLE.md #13): one warm-up,
// then the median and the spread (min..max) of `runs` timed runs; and the
// machine's name for the report.
#pragma once

#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
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

}  // namespace brume::bench
