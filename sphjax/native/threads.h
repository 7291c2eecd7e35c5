// How sphjax's compiled loops share rows between threads: XLA's own CPU thread pool (its
// threads would otherwise spin beside ours), at most $SPHJAX_NATIVE_THREADS of them.
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>

#include "xla/ffi/api/ffi.h"

namespace sphjax_native {

// Run body(t) for t < threads: the calling thread takes parts t in turn until none is left,
// and XLA's CPU pool is asked for threads - 1 helpers that take parts too.  The caller
// waits only for parts a helper has taken (they are running), never for a helper to
// start: XLA may run two of our calls at once on its only two threads, and each waiting
// for the other's pool would never return.  A helper that starts after every part is
// taken returns at once, touching only the shared counters (kept alive by the helpers).
// The body is called through a plain function pointer, so this machinery is compiled once
// for every loop, not once per loop (it was most of the library's code and build time).
inline void in_parallel_erased(xla::ffi::ThreadPool* pool, int64_t threads,
                               void (*call)(void*, int64_t), void* body) {
  struct Parts {
    std::atomic<int64_t> next{0};
    int64_t done = 0;
    std::mutex mutex;
    std::condition_variable finished;
  };
  auto parts = std::make_shared<Parts>();
  auto take = [threads, call, body](const std::shared_ptr<Parts>& parts) {
    for (int64_t t = parts->next.fetch_add(1); t < threads; t = parts->next.fetch_add(1)) {
      call(body, t);
      std::lock_guard<std::mutex> lock(parts->mutex);
      if (++parts->done == threads) parts->finished.notify_one();
    }
  };
  for (int64_t t = 1; t < threads; t++) pool->Schedule([parts, take] { take(parts); });
  take(parts);
  std::unique_lock<std::mutex> lock(parts->mutex);
  parts->finished.wait(lock, [&] { return parts->done == threads; });
}

// body(t) for t < threads (in_parallel_erased with the body's type restored)
template <typename Body>
void in_parallel(xla::ffi::ThreadPool* pool, int64_t threads, Body body) {
  in_parallel_erased(
      pool, threads, [](void* b, int64_t t) { (*static_cast<Body*>(b))(t); }, &body);
}

// How many threads share n rows: XLA's pool's size (at most $SPHJAX_NATIVE_THREADS), at
// least 1024 rows each.
inline int64_t thread_count(xla::ffi::ThreadPool* pool, int64_t n) {
  int64_t threads = pool == nullptr ? 1 : std::max<int64_t>(1, pool->num_threads());
  if (const char* env = std::getenv("SPHJAX_NATIVE_THREADS"))
    threads = std::min<int64_t>(threads, std::max<int64_t>(1, std::atoll(env)));
  return std::min<int64_t>(threads, std::max<int64_t>(1, n / 1024));
}

}  // namespace sphjax_native
