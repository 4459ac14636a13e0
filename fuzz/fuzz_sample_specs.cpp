// Sampler ranges (brume sample, Python brume.sample): lines "name=spec" for
// one effect (the first byte picks it), resolved and parsed as the sampler
// does, then one draw checked by the effect's own validation.
#include "brume/error.hpp"
#include "brume/sample.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const auto& effects = brume::sample_effects();
  const std::string effect = effects[data[0] % effects.size()];
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  std::map<std::string, std::string> specs;
  std::size_t at = 0;
  while (at <= text.size()) {
    std::size_t nl = text.find('\n', at);
    if (nl == std::string::npos) nl = text.size();
    const std::string line = text.substr(at, nl - at);
    const auto eq = line.find('=');
    if (eq != std::string::npos) specs[line.substr(0, eq)] = line.substr(eq + 1);
    at = nl + 1;
  }
  try {
    brume::resolve_sample_specs(effect, specs);
    brume::random_params(effect, 7, "frame-0", specs);
  } catch (const brume::Error&) {
  }
  return 0;
}
