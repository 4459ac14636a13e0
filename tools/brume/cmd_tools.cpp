// brume demo / brume study — the built-in scene and the diffusion study.
// They are tools around the effects, not effects: their few flags are
// declared here (run_demo and run_study live with their modules).
#include <memory>

#include "brume_study/study.hpp"
#include "cli.hpp"
#include "demo.hpp"

namespace brume::cli {

Command add_demo(CLI::App& app) {
  CLI::App* demo = app.add_subcommand("demo", "render the built-in RGB-D scene clean, with haze and with fog");
  struct Args {
    std::string dir;
    int w = 960, h = 672, threads = 0;
  };
  auto a = std::make_shared<Args>();
  demo->add_option("--out-dir", a->dir, "directory for the images (created if missing)")->required();
  demo->add_option("--width", a->w, "width in pixels")->capture_default_str();
  demo->add_option("--height", a->h, "height in pixels")->capture_default_str();
  demo->add_option("--threads", a->threads, "worker threads (0 = all)")->capture_default_str();
  return {demo, "demo", [a](const std::vector<std::string>&) {
            const IoThreads io(a->threads);  // its files' coding too, as every job's
            return run_demo(a->dir, a->w, a->h, a->threads);
          }};
}

Command add_study(CLI::App& app) {
  CLI::App* study = app.add_subcommand("study", "accuracy and speed studies (Hansard 5.2-5.3)");
  struct Args {
    std::string what, dir, backend = "cpu", image, only = "all";
    bool quick = false;
  };
  auto a = std::make_shared<Args>();
  study->add_option("what", a->what, "the study: diffusion")->required();
  study->add_option("--out-dir", a->dir, "directory for accuracy.csv and speed.csv")->required();
  study->add_flag("--quick", a->quick, "small image and a few sigma (a smoke test)");
  study->add_option("--backend", a->backend, "cpu, gpu or all")->capture_default_str();
  study->add_option("--image", a->image, "real image in [0,1] for the accuracy part (default Middlebury Art)");
  study->add_option("--only", a->only, "all, or leakage: the leakage experiment alone (leakage.csv, leakage.png)")
      ->capture_default_str();
  return {study, "study", [a](const std::vector<std::string>&) {
            return run_study(a->what, a->dir, a->quick, a->backend, a->image, a->only);
          }};
}

}  // namespace brume::cli
