// The bounding-box tree over the patches, for finding what lies near a hemicube.
#include "solver_impl.h"

#include <glm/common.hpp>

#include <limits>

namespace hemibake::solver {

void Solver::Impl::build_patch_tree(uint32_t id, uint32_t begin, uint32_t end) {
  BoxNode node;
  node.begin = begin;
  node.end = end;
  node.lo = glm::dvec3(std::numeric_limits<double>::max());
  node.hi = glm::dvec3(std::numeric_limits<double>::lowest());
  glm::dvec3 clo = node.lo, chi = node.hi;  // of the boxes' centres (doubled)
  for (uint32_t i = begin; i < end; ++i) {
    const uint32_t q = tree_patch[i];
    node.lo = glm::min(node.lo, p_lo[q]);
    node.hi = glm::max(node.hi, p_hi[q]);
    clo = glm::min(clo, p_lo[q] + p_hi[q]);
    chi = glm::max(chi, p_lo[q] + p_hi[q]);
  }
  if (end - begin > 4) {
    const uint32_t mid =
        median_cut(tree_patch, begin, end, clo, chi, [&](uint32_t q) { return p_lo[q] + p_hi[q]; });
    node.child = static_cast<uint32_t>(tree.size());
    tree.resize(tree.size() + 2);
    build_patch_tree(node.child, begin, mid);
    build_patch_tree(node.child + 1, mid, end);
  }
  tree[id] = node;
}

}  // namespace hemibake::solver
