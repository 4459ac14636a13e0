// brume demo — entry point of `brume demo` (tools/brume/demo.cpp).
#pragma once

#include <string>

// Renders the procedural demo scene at width x height (16..16384) into dir
// (created if missing): clean, hazy and foggy images, the range map and their
// parameter records. threads: worker threads, 0 = all. Returns the exit status.
int run_demo(const std::string& dir, int width, int height, int threads);
