#include "caps/app/loaded_model.hpp"

#include "caps/surface/patient_model.hpp"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <utility>
#include <vector>

namespace caps::app {

namespace fs = std::filesystem;

namespace {

// What identifies one version of a model folder's files: each regular file's name, size and
// modification time, in directory order sorted by name.
using Stamp = std::vector<std::pair<std::string, std::pair<std::uintmax_t, std::int64_t>>>;

Stamp stamp_of(const fs::path& dir) {
  Stamp stamp;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code fe;
    if (!it->is_regular_file(fe)) continue;
    const auto size = it->file_size(fe);
    const auto time = it->last_write_time(fe).time_since_epoch();
    stamp.push_back({it->path().filename().string(),
                     {size, std::chrono::duration_cast<std::chrono::nanoseconds>(time).count()}});
  }
  std::sort(stamp.begin(), stamp.end());
  return stamp;
}

struct Entry {
  std::string key;
  Stamp stamp;
  std::shared_ptr<const PatientModel> model;
};

constexpr std::size_t kMaxModels = 4;  // a server has one; tests and benchmarks a few

}  // namespace

std::shared_ptr<const PatientModel> loaded_model(const std::string& dir) {
  static std::mutex mutex;
  static std::vector<Entry> cache;  // most recently used last
  std::error_code ec;
  const std::string key = fs::weakly_canonical(fs::path(dir), ec).string();
  Stamp stamp = stamp_of(dir);
  {
    std::lock_guard<std::mutex> lock(mutex);
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->key == key && it->stamp == stamp) {
        Entry e = std::move(*it);
        cache.erase(it);
        cache.push_back(std::move(e));
        return cache.back().model;
      }
  }
  // Read outside the lock: a slow load does not hold up requests on another model.
  auto model = std::make_shared<const PatientModel>(PatientModel::load(dir));
  std::lock_guard<std::mutex> lock(mutex);
  cache.erase(std::remove_if(cache.begin(), cache.end(),
                             [&](const Entry& e) { return e.key == key; }),
              cache.end());
  if (cache.size() >= kMaxModels) cache.erase(cache.begin());
  cache.push_back({key, std::move(stamp), model});
  return model;
}

}  // namespace caps::app
