// The fog's density table (brume fog --table): height_m,density_per_m rows.
#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-fog.csv");
  brume::fuzz::write_file(path, data, size);
  try {
    const brume::DensityTable t = brume::read_density_table(path);
    // Accepted tables are what the fog integrates: non-empty, finite, increasing heights.
    if (t.height_m.empty() || t.height_m.size() != t.density_per_m.size()) std::abort();
    for (std::size_t i = 1; i < t.height_m.size(); ++i)
      if (!(t.height_m[i] > t.height_m[i - 1])) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
