// brume._brume — fork safety (issue #42 item 5).
//
// The library's threads are OpenMP's (libgomp). libgomp keeps a pool of
// worker threads per thread that opened a parallel region; fork() copies the
// pool's bookkeeping into the child but not its threads, so the child's next
// parallel region of more than one thread on that thread waits on a barrier
// that no thread will ever reach: a process that ran an effect and then forks
// workers (multiprocessing's "fork" start method, torch's DataLoader) hangs in
// the workers' first effect. libgomp has no call that resets the pool.
//
// What is safe in the child: a region of one thread (libgomp returns before
// it touches the pool), and any region opened by a thread created after the
// fork (its pool is its own, made fresh). So, in a forked child:
//  - threads=0 ("all cores") means one thread: a worker process is already
//    one of several, and one thread per worker is what a loader wants;
//  - threads=N > 1, asked for explicitly, runs the library on a thread made
//    for the call (its own pool; the call's cost grows by creating N - 1
//    threads, tens of microseconds).
// A pthread_atfork child handler marks the process; it runs in the child
// before fork() returns there, whatever forked (os.fork, multiprocessing,
// a C library).
#include <pthread.h>

#include <atomic>
#include <exception>
#include <thread>

#include "binding.hpp"

namespace brume::python {

namespace {
std::atomic<bool> g_forked_child{false};
void mark_forked_child() { g_forked_child.store(true); }
}  // namespace

void install_fork_handlers() {
  static const bool installed = [] { return pthread_atfork(nullptr, nullptr, &mark_forked_child) == 0; }();
  if (!installed) throw Error("internal: pthread_atfork failed; brume cannot make forked workers safe");
}

bool in_forked_child() { return g_forked_child.load(); }

Exec fork_safe(Exec e) {
  if (in_forked_child() && e.threads == 0) e.threads = 1;
  return e;
}

void run_fork_safe(const Exec& e, const std::function<void()>& f) {
  if (!in_forked_child() || e.threads == 1) {
    f();
    return;
  }
  std::exception_ptr err;
  std::thread t([&] {
    try {
      f();
    } catch (...) {
      err = std::current_exception();
    }
  });
  t.join();
  if (err) std::rethrow_exception(err);
}

}  // namespace brume::python
