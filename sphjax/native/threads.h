// How sphjax's compiled loops share rows between threads: XLA's own CPU thread pool (its
// threads would otherwise spin beside ours), at most $SPHJAX_NATIVE_THREADS of them.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <mutex>

#include "xla/ffi/api/ffi.h"

namespace sphjax_native {

// Run body(t) for t < threads: t = 0 on the calling thread, the others on XLA's CPU pool,
// and wait for them.
template <typename Body>
void in_parallel(xla::ffi::ThreadPool* pool, int64_t threads, Body body) {
  std::mutex mutex;
  std::condition_variable done;
  int64_t remaining = threads - 1;
  for (int64_t t = 1; t < threads; t++)
    pool->Schedule([&, t] {
      body(t);
      std::lock_guard<std::mutex> lock(mutex);
      if (--remaining == 0) done.notify_one();
    });
  body(0);
  std::unique_lock<std::mutex> lock(mutex);
  done.wait(lock, [&] { return remaining == 0; });
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
