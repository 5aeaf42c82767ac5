#include "output_check.hpp"

#include <filesystem>
#include <system_error>

#include "caps/core/error.hpp"

namespace fs = std::filesystem;

namespace caps::app::detail {
namespace {

// The absolute, symlink-free form of `p`; for a path that does not exist yet, its existing
// parent's canonical form joined with the rest.
fs::path canonical_or_weak(const fs::path& p) {
  std::error_code ec;
  const fs::path c = fs::weakly_canonical(fs::absolute(p, ec), ec);
  return ec ? fs::absolute(p).lexically_normal() : c;
}

// True if `inner` is `outer` or lies inside it.
bool is_within(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty() && std::next(o) == outer.end()) break;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

void refuse_output_over_inputs(const std::string& output,
                               const std::vector<std::pair<std::string, std::string>>& inputs) {
  const fs::path out = canonical_or_weak(output);
  for (const auto& [field, value] : inputs) {
    std::error_code ec;
    if (!fs::exists(value, ec)) continue;
    const fs::path in = canonical_or_weak(value);
    if (in == out)
      throw InvalidInput(cat("the output ", output, " is the input ", field, " ", value,
                             "; writing it would destroy the input (even with --force): choose "
                             "another output"));
    if (is_within(in, out))
      throw InvalidInput(cat("the output ", output, " holds the input ", field, " ", value,
                             "; replacing it would destroy the input (even with --force): choose "
                             "another output"));
  }
}

}  // namespace caps::app::detail
