// brume — execution options shared by every effect (the same trailing
// argument on every apply function, as in OpenImageIO's ImageBufAlgo).
#pragma once

namespace brume {

enum class Path {
  fast,       // multithreaded, vectorised float path (default)
  reference,  // plain scalar double-precision path, kept forever as the oracle
};

struct Exec {
  int threads = 0;         // 0 = all hardware threads; results never depend on it
  Path path = Path::fast;
};

}  // namespace brume
