#pragma once
/// @brief Disjoint sets of ids 0..n-1 (union-find with path halving); each set's root is its
/// smallest member. Used by the solver's suture groups, the CalculiX export and the mesher.

#include <algorithm>
#include <cstddef>
#include <numeric>
#include <vector>

namespace caps {

struct UnionFind {
  std::vector<int> p;
  explicit UnionFind(int n) : p(static_cast<std::size_t>(n)) { std::iota(p.begin(), p.end(), 0); }
  int find(int x) {
    while (p[x] != x) x = p[x] = p[p[x]];
    return x;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a != b) p[std::max(a, b)] = std::min(a, b);
  }
};

}  // namespace caps
