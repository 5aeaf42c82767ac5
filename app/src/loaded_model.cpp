#include "caps/app/loaded_model.hpp"

#include "caps/mesher/tissue_model.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/model_dir.hpp"

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

// One kind of content read from a folder, kept while none of the folder's files changes.
template <class T>
class FolderCache {
 public:
  template <class Load>
  std::shared_ptr<const T> get(const std::string& dir, Load&& load) {
    std::error_code ec;
    const std::string key = fs::weakly_canonical(fs::path(dir), ec).string();
    Stamp stamp = stamp_of(dir);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (auto it = cache_.begin(); it != cache_.end(); ++it)
        if (it->key == key && it->stamp == stamp) {
          Entry e = std::move(*it);
          cache_.erase(it);
          cache_.push_back(std::move(e));
          return cache_.back().value;
        }
    }
    // Read outside the lock: a slow load does not hold up requests on another model.
    std::shared_ptr<const T> value = load();
    std::lock_guard<std::mutex> lock(mutex_);
    cache_.erase(std::remove_if(cache_.begin(), cache_.end(),
                                [&](const Entry& e) { return e.key == key; }),
                 cache_.end());
    if (cache_.size() >= kMaxModels) cache_.erase(cache_.begin());
    cache_.push_back({key, std::move(stamp), value});
    return value;
  }

 private:
  struct Entry {
    std::string key;
    Stamp stamp;
    std::shared_ptr<const T> value;
  };
  static constexpr std::size_t kMaxModels = 4;  // a server has one; tests and benchmarks a few
  std::mutex mutex_;
  std::vector<Entry> cache_;  // most recently used last
};

}  // namespace

std::shared_ptr<const PatientModel> loaded_model(const std::string& dir) {
  static FolderCache<PatientModel> cache;
  return cache.get(dir, [&] { return std::make_shared<const PatientModel>(PatientModel::load(dir)); });
}

std::shared_ptr<const mesher::TissueModel> loaded_tissue_model(const std::string& dir) {
  static FolderCache<mesher::TissueModel> cache;
  return cache.get(dir, [&] {
    return std::make_shared<const mesher::TissueModel>(mesher::read_tissue_model(dir));
  });
}

std::shared_ptr<const render::DrawnSkin> loaded_drawn_skin(const std::string& dir) {
  static FolderCache<render::DrawnSkin> cache;
  return cache.get(dir, [&] {
    return std::make_shared<const render::DrawnSkin>(render::load_drawn_skin(*loaded_model(dir), dir));
  });
}

std::shared_ptr<const FeatureLines> loaded_feature_lines(const std::string& dir) {
  static FolderCache<FeatureLines> cache;
  return cache.get(dir, [&] {
    // A model made before feature lines were found has none: nothing is reported for them.
    const ModelInfo info = read_model_info(dir);
    return std::make_shared<const FeatureLines>(
        info.features_json.empty()
            ? FeatureLines{}
            : feature_lines_from_json(info.features_json, (fs::path(dir) / "model.json").string()));
  });
}

}  // namespace caps::app
