// brume sample — the parameters the sampler draws for a frame (brume/sample.hpp),
// as JSON on stdout: what `brume batch` and brume.random_params give that frame.
#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/sample.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_sample(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "sample", "draw an effect's parameters for a frame, keyed by (seed, key, parameter name), as JSON");
  struct Args {
    std::string effect, key;
    std::uint64_t seed = 0;
    std::vector<std::string> params;
    int count = 0;
  };
  auto a = std::make_shared<Args>();
  std::string effects;
  for (const std::string& e : sample_effects()) effects += (effects.empty() ? "" : ", ") + e;
  sub->add_option("--effect", a->effect, "the effect: " + effects)->required();
  sub->add_option("--seed", a->seed, "the dataset's seed (a non-negative integer)")->required();
  sub->add_option("--key", a->key, "the frame's key (the manifest's key, e.g. Art/view1.png)")->required();
  sub->add_option("--param", a->params,
                  "NAME=SPEC, repeatable: a fixed value, uniform(a, b), loguniform(a, b), choice(x, y, ...) or seed() (a "
                  "whole number per key); "
                  "overrides or extends the effect's default ranges (shown under sampling.specs)");
  sub->add_option("--count", a->count,
                  "draw for keys KEY#0 ... KEY#(N-1) instead, one JSON object per line (a quick look at the spread)")
      ->check(CLI::PositiveNumber);
  return {sub, "sample", [a](const std::vector<std::string>&) {
            std::map<std::string, std::string> specs;
            for (const std::string& p : a->params) {
              const auto eq = p.find('=');
              if (eq == std::string::npos || eq == 0)
                throw Error("--param '" + p + "' must be NAME=SPEC, e.g. visibility=loguniform(100, 2000)");
              const std::string name = p.substr(0, eq);
              if (specs.count(name)) throw Error("--param " + name + " is given twice; give each parameter once");
              specs[name] = p.substr(eq + 1);
            }
            auto one = [&](const std::string& key) {
              return nlohmann::json{{"effect", a->effect},
                                    {"key", key},
                                    {"params", random_params(a->effect, a->seed, key, specs)},
                                    {"sampling", sample_provenance(a->effect, a->seed, key, specs)}};
            };
            // Everything is drawn (and checked) before anything is printed.
            std::string out;
            if (a->count == 0) {
              out = one(a->key).dump(2) + "\n";
            } else {
              for (int i = 0; i < a->count; ++i) out += one(a->key + "#" + std::to_string(i)).dump() + "\n";
            }
            std::fputs(out.c_str(), stdout);
            return 0;
          }};
}

}  // namespace brume::cli
