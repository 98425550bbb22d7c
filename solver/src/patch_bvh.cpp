// The bounding-box tree over the patches (median cuts), for finding what lies near a hemicube.
#include "solver_impl.h"

#include <glm/common.hpp>

#include <limits>

namespace hemibake::solver {

// Per patch its bounding box, and the tree over them.
void Solver::Impl::build_patch_bvh() {
  p_lo.resize(patches.size());
  p_hi.resize(patches.size());
  tree_patch.resize(patches.size());
  for (uint32_t q = 0; q < patches.size(); ++q) {
    tree_patch[q] = q;
    p_lo[q] = p_hi[q] = patches[q].corners[0];
    for (uint32_t k = 1; k < patches[q].corner_count; ++k) {
      p_lo[q] = glm::min(p_lo[q], patches[q].corners[k]);
      p_hi[q] = glm::max(p_hi[q], patches[q].corners[k]);
    }
  }
  tree.emplace_back();
  if (!patches.empty()) build_patch_tree(0, 0, static_cast<uint32_t>(patches.size()));
}

// Tree node `id` over tree_patch[begin, end), and its subtree: leaves hold at most four patches.
void Solver::Impl::build_patch_tree(uint32_t id, uint32_t begin, uint32_t end) {
  HEMIBAKE_DCHECK(begin < end && end <= tree_patch.size() && id < tree.size());
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

// Appends the patches whose boxes meet the shaft's to `out` and marks them (p_mark = mark), in
// the tree's order: the hemicube projects in this order, and ties in depth keep it.
void Solver::Impl::patches_meeting(const detail::Shaft& shaft, std::vector<uint32_t>& out) {
  const double slack = kRoundingLength * prep.diagonal;
  std::vector<uint32_t> nodes{0};
  while (!nodes.empty()) {
    const BoxNode& node = tree[nodes.back()];
    nodes.pop_back();
    if (!shaft.meets(node.lo, node.hi, slack)) continue;
    if (node.child != kNone) {
      nodes.push_back(node.child + 1);
      nodes.push_back(node.child);
      continue;
    }
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const uint32_t q = tree_patch[i];
      if (shaft.meets(p_lo[q], p_hi[q], slack)) {
        out.push_back(q);
        p_mark[q] = mark;
      }
    }
  }
}

}  // namespace hemibake::solver
