// brume._brume — one GPU context per Python thread.
#include "binding.hpp"

#include "brume/error.hpp"

namespace brume::python {

// ==== one GPU context per thread ==========================================================
// A context belongs to the thread that made it (EGL makes it current there),
// so each Python thread gets its own: made lazily, without the GIL, by its
// first call with backend gpu/auto, and reused by its later calls --
// per-call creation cost tens of ms (llvmpipe: ~30-60 ms). The thread_local
// is destroyed at the thread's exit, on that thread (the main thread's at
// process exit, before the atexit handlers of the GL driver). A thread on
// which creation failed does not retry here: choose_backend then makes its
// own attempt per call and reports it exactly as before (auto: CPU with the
// reason in the record; gpu: RuntimeError).
thread_local std::unique_ptr<GpuContext> t_gpu;
GpuContext* thread_gpu(const Exec& exec) {
  std::unique_ptr<GpuContext>& ctx = t_gpu;
  thread_local bool failed = false;
  if (exec.backend == Backend::cpu || exec.path == Path::reference || exec.gpu) return exec.gpu;
  if (!ctx && !failed) {
    try {
      ctx = std::make_unique<GpuContext>();
    } catch (const Error&) {
      failed = true;
    }
  }
  return ctx.get();
}
// The execution options of a call with this thread's context (call without the GIL).
Exec with_thread_gpu(Exec e) {
  e.gpu = thread_gpu(e);
  return e;
}

}  // namespace brume::python
