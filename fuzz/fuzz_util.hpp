// brume fuzz targets: the fuzzer's bytes become a file, because every parser
// brume owns reads a path (as users give it). The file lives in /dev/shm when
// available (no disk traffic at ~10^4 executions per second) and is named
// per process, so parallel fuzzing jobs (-jobs=N) never share one.
//
// The contract every target checks: a parser returns or throws brume::Error
// (a message for the user). Any other exception escapes the target, which
// libFuzzer reports as a crash, because the CLI would print it as "internal
// error" (exit 3): a parser bug. Sanitizer reports and signals are crashes too.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

namespace brume::fuzz {

inline std::string temp_path(const std::string& suffix) {
  std::error_code ec;
  const std::string dir = std::filesystem::is_directory("/dev/shm", ec) ? "/dev/shm" : "/tmp";
  return dir + "/brume-fuzz-" + std::to_string(::getpid()) + suffix;
}

// Writes the bytes to `path` (truncating) and returns it.
inline const std::string& write_file(const std::string& path, const std::uint8_t* data, std::size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace brume::fuzz
