// What a hemicube must see: every accepted receiver, and whatever may stand between one and the
// shooting piece (shaft.h).
#include "solver_impl.h"

#include <algorithm>
#include <utility>

namespace hemibake::solver {

// The boxes of a near-field hemicube's shaft: per surface of the receivers, the joint bounding box
// of the piece and that surface's receivers. Too many surfaces are merged into fewer boxes (still
// conservative). A whole-scene hemicube gets none: it sees everything.
detail::Shaft Solver::Impl::shaft_of(const Piece& piece, const std::vector<uint32_t>& accepted, bool whole_scene) const {
  using detail::Box;
  detail::Shaft shaft;
  shaft.whole_scene = whole_scene;
  if (whole_scene) return shaft;
  std::vector<Box>& boxes = shaft.boxes;
  Box piece_box;
  for (const glm::dvec3& x : piece.points) piece_box.add(x);
  // Per surface met, its box (in the order met), found through a per-thread slot per surface id;
  // then the boxes in increasing surface id. A box is a bound, the same whatever order its
  // receivers come in; sorting the receivers by surface was a fiftieth of a cluttered room's bake.
  thread_local std::vector<uint64_t> slot_stamp;
  thread_local std::vector<uint32_t> slot;
  thread_local uint64_t box_stamp = 0;
  ++box_stamp;
  std::vector<std::pair<uint32_t, Box>> by_group;  // (surface, its receivers' box)
  for (uint32_t e : accepted) {
    const uint32_t g = prep.occlusion_group[e_patch[e]];
    if (g >= slot.size()) {
      slot.resize(g + 1, 0);
      slot_stamp.resize(g + 1, 0);
    }
    if (slot_stamp[g] != box_stamp) {
      slot_stamp[g] = box_stamp;
      slot[g] = static_cast<uint32_t>(by_group.size());
      by_group.emplace_back(g, piece_box);
    }
    Box& box = by_group[slot[g]].second;
    for (uint32_t k = 0; k < corner_count(e); ++k) box.add(vpos[e_corner[e][k]]);
  }
  std::sort(by_group.begin(), by_group.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  boxes.reserve(by_group.size());
  for (const auto& [g, box] : by_group) boxes.push_back(box);
  while (boxes.size() > kMaxShaftBoxes) {
    for (size_t i = 0; i + 1 < boxes.size(); i += 2) boxes[i / 2] = [&] { Box b = boxes[i]; b.add(boxes[i + 1]); return b; }();
    if (boxes.size() % 2) boxes[boxes.size() / 2] = boxes.back();
    boxes.resize((boxes.size() + 1) / 2);
  }
  return shaft;
}

// Fills `seen` with what the hemicube projects: the receivers, and as occluders, of everything
// overlapping the shaft, the largest elements that hold no receiver (the leaves of a subdivided
// patch tile it, so one polygon hides what they hide, and a pixel gets one fragment where it got
// many).
void Solver::Impl::gather_seen(const detail::Shaft& shaft, const std::vector<uint32_t>& accepted,
                               std::vector<uint32_t>& seen) {
  seen.clear();
  ++mark;
  for (uint32_t e : accepted)
    for (uint32_t x = e; x != kNone && e_mark[x] != mark; x = e_parent[x]) e_mark[x] = mark;
  // The patches whose boxes meet the shaft (all of them for a whole-scene hemicube).
  std::vector<uint32_t> near_patches;
  if (!shaft.whole_scene) {
    patches_meeting(shaft, near_patches);
    // The receivers' patches always count (rounding of shared vertices must not lose one).
    for (uint32_t e : accepted) {
      const uint32_t q = e_patch[e];
      if (p_mark[q] != mark) {
        near_patches.push_back(q);
        p_mark[q] = mark;
      }
    }
  }
  // Each patch's quadtree on its own, so the patches are shared among the threads (their lists
  // joined in order).
  const std::vector<uint32_t>& patch_list = shaft.whole_scene ? tree_patch : near_patches;
  pool.parallel_for(patch_list.size(), [&](size_t begin, size_t end, size_t c) {
    std::vector<uint32_t>& out = gather_chunks[c];
    out.clear();
    std::vector<uint32_t> stack;
    for (size_t i = begin; i < end; ++i) {
      stack.push_back(p_root[patch_list[i]]);
      while (!stack.empty()) {
        const uint32_t x = stack.back();
        stack.pop_back();
        if (e_mark[x] != mark) {
          if (shaft.overlaps(e_centre[x], e_radius[x])) out.push_back(x);
        } else if (e_child[x] == kNone) {
          out.push_back(x);  // a receiver
        } else {
          for (uint32_t k = 4; k-- > 0;) stack.push_back(e_child[x] + k);
        }
      }
    }
  });
  for (size_t c = 0; c < pool.chunk_count(patch_list.size()); ++c)
    seen.insert(seen.end(), gather_chunks[c].begin(), gather_chunks[c].end());
}

}  // namespace hemibake::solver
