// brume — a run's warnings on stderr (core/warnings.hpp).
#include "core/warnings.hpp"

#include <cstdio>
#include <utility>

namespace brume {

namespace {
thread_local FrameWarnings* current_frame = nullptr;
}  // namespace

FrameWarnings::FrameWarnings(std::string key) : key_(std::move(key)), outer_(current_frame) { current_frame = this; }

FrameWarnings::~FrameWarnings() { current_frame = outer_; }

void print_warning(const std::string& command, const std::string& text) {
  const std::string who = command.empty() ? "brume" : "brume " + command;
  if (FrameWarnings* f = current_frame) {
    f->texts_.push_back(text);
    std::fprintf(stderr, "%s: frame '%s': warning: %s\n", who.c_str(), f->key_.c_str(), text.c_str());
  } else {
    std::fprintf(stderr, "%s: warning: %s\n", who.c_str(), text.c_str());
  }
}

}  // namespace brume
