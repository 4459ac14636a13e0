// brume batch — a dataset in one process (brume/batch.hpp): a manifest's
// frames through the effects' pipelines, sampled parameters, shards, resume.
// Exit status: 0 every frame done (or skipped as done), 1 some frames failed
// (the summary and the results manifest say which), 2 nothing could run.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "brume/batch.hpp"
#include "brume/error.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_batch(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "batch", "run a manifest of frames (CSV or JSON Lines) in one process: sampled parameters, workers, resume, "
               "shards; or a dataset's folder into a manifest (--dataset)");
  struct Args {
    BatchOptions o;
    std::string shard = "1/1";
    std::vector<std::string> params;
    bool quiet = false;
    DatasetOptions dataset;
  };
  auto a = std::make_shared<Args>();
  std::string effects;
  for (const std::string& e : batch_effects()) effects += (effects.empty() ? "" : ", ") + e;
  sub->add_option("--manifest", a->o.manifest,
                  "the manifest: .csv (header row) or .jsonl; one frame per row: key, image, depth flags without "
                  "dashes, effect, parameters (fixed or uniform(a, b), loguniform(a, b), choice(x, y, ...)). With "
                  "--dataset: the manifest to write")
      ->required();
  sub->add_option("--out-dir", a->o.out_dir, "outputs, records and results.jsonl go here, named after the keys");
  sub->add_option("--workers", a->o.workers, "frames in flight (0 = one per core)")->default_str("0");
  sub->add_flag("--resume", a->o.resume,
                "skip frames already done: output and record present, same job, inputs' SHA-256 unchanged");
  sub->add_option("--shard", a->shard,
                  "I/N: only the frames whose key hashes to shard I of N (Slurm: $SLURM_ARRAY_TASK_ID/N)")
      ->default_str("1/1");
  sub->add_option("--seed", a->o.seed, "the dataset's seed for sampled parameters")->default_str("0");
  sub->add_option("--format", a->o.format,
                  "output format by extension (png, exr, ...); default the input's. PNG frames are written at "
                  "--compression fast (Up filter, run-length deflate: fast to write and read) unless a column or --param "
                  "compression=... says otherwise");
  sub->add_option("--effect", a->o.effect, "effect for rows without an 'effect' column: " + effects);
  sub->add_option("--param", a->params,
                  "NAME=SPEC, repeatable: a parameter for rows without that column (a chain's later stage "
                  "prefixed: dof.focus-distance=loguniform(1, 20))");
  sub->add_option("--map", a->o.maps, "also write this map of the effect for every frame (e.g. transmission), as "
                                      "<key>.<map>.exr; repeatable");
  sub->add_flag("--quiet", a->quiet, "no progress lines (failures and the summary are still printed)");
  sub->add_option("--dataset,--scan", a->dataset.dir,
                  "write --manifest from this dataset folder instead (with --out-dir: then run it); --scan is its "
                  "former name");
  sub->add_option("--layout", a->dataset.layout, "the --dataset folder's layout: middlebury, eth3d, kitti, cityscapes, pairs");
  sub->add_option("--image-glob", a->dataset.image_glob, "pairs: images relative to --dataset, e.g. 'rgb/*.png'");
  sub->add_option("--depth-glob", a->dataset.depth_glob,
                  "pairs: depth files relative to --dataset, paired by what '*' matched, e.g. 'depth/*.exr'");
  sub->add_flag("--lidar", a->dataset.lidar,
                "with --dataset --layout kitti: also a 'lidar' column (velodyne/N.bin): each frame's scan is fogged with "
                "its image's medium and written beside it as <key>.bin (docs/lidar.md)");
  sub->add_option("--depth-kind", a->dataset.depth_kind, "pairs: the depth column (range, z, disparity, ...)")
      ->default_str("range");
  auto eflags = std::make_shared<Flags<ExecOptions>>(sub, exec_param_table());
  return {sub, "batch", [a, eflags](const std::vector<std::string>&) {
            BatchOptions o = a->o;
            eflags->apply(o.exec);
            o.progress = !a->quiet;
            const auto slash = a->shard.find('/');
            try {
              if (slash == std::string::npos) throw std::invalid_argument("no /");
              std::size_t i1 = 0, i2 = 0;
              o.shard_index = std::stoi(a->shard.substr(0, slash), &i1);
              o.shard_count = std::stoi(a->shard.substr(slash + 1), &i2);
              if (i1 != slash || i2 != a->shard.size() - slash - 1) throw std::invalid_argument("trailing");
            } catch (const std::exception&) {
              throw Error("--shard '" + a->shard + "' is not I/N (e.g. 2/8)");
            }
            for (const std::string& p : a->params) {
              const auto eq = p.find('=');
              if (eq == std::string::npos || eq == 0)
                throw Error("--param '" + p + "' is not NAME=SPEC (e.g. visibility=loguniform(50, 5000))");
              o.params.emplace_back(p.substr(0, eq), p.substr(eq + 1));
            }
            if (!a->dataset.dir.empty()) {
              DatasetOptions s = a->dataset;
              if (s.layout.empty()) throw Error("--dataset needs --layout middlebury|eth3d|kitti|cityscapes|pairs");
              s.manifest_dir = std::filesystem::path(o.manifest).parent_path().string();
              const auto rows = dataset_manifest(s);
              write_manifest(o.manifest, rows);
              std::fprintf(stderr, "brume batch: %zu frames of '%s' (%s) written to %s\n", rows.size(), s.dir.c_str(),
                           s.layout.c_str(), o.manifest.c_str());
              if (o.out_dir.empty()) return 0;
            } else if (!a->dataset.layout.empty()) {
              throw Error("--layout is for --dataset DIR; give the dataset's folder");
            }
            if (o.out_dir.empty()) throw Error("--out-dir is required: the folder the outputs and records go to");
            const BatchSummary s = run_batch(o);
            std::fprintf(stderr, "brume batch: %zu frames in %.1f s: %zu done, %zu skipped (done before), %zu failed%s; %s\n",
                         s.frames, s.seconds, s.ok, s.skipped, s.failed,
                         s.warned ? (", " + std::to_string(s.warned) + " with warnings (each frame's results line lists them)").c_str()
                                  : "",
                         s.results.c_str());
            return s.failed > 0 ? 1 : 0;
          }};
}

}  // namespace brume::cli
