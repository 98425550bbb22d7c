// glTF 2.0 in (patches for the solver) and baked glTF out (the radiosity mesh with per-vertex
// colours, optionally Draco-compressed).
#pragma once

#include "hemibake/protocol/method.h"
#include "hemibake/protocol/tone.h"
#include "hemibake/solver/solver.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace hemibake::protocol {

/// Bounds on untrusted input.
struct LoadLimits {
  uint64_t max_file_bytes = 512ull << 20;  ///< the .glb/.gltf file itself
  uint64_t max_triangles = 2'000'000;      ///< triangles in the scene, instances counted
  uint32_t max_image_pixels = 8192 * 8192; ///< per texture image (a larger one counts as white, with a warning)
  uint64_t max_total_image_pixels = 4ull * 8192 * 8192;  ///< all images together, decoded (4 bytes each);
                                                         ///< more is an error
  bool allow_external_files = true;        ///< .gltf buffers and images beside the file; false
                                           ///< accepts only embedded (GLB or data-URI) data
};

/// A parsed glTF file and the patches it becomes. Opaque; made by load_gltf_*.
class SceneDocument;

struct LoadResult {
  std::shared_ptr<const SceneDocument> document;  ///< null on error
  std::string error;                  ///< on failure: the glTF object at fault and what is wrong
  std::vector<std::string> warnings;  ///< what was skipped or approximated
};

/// Reads a .glb or .gltf file (by its content; `path`'s folder holds a .gltf's external files).
LoadResult load_gltf_file(const std::string& path, const LoadLimits& limits = {});

/// Reads glTF from memory; `base_dir` is where external files are looked for (if allowed).
LoadResult load_gltf_memory(std::span<const uint8_t> bytes, const std::string& base_dir,
                            const LoadLimits& limits = {});

/// The patches to bake (world space). Valid as long as the document lives.
const solver::Scene& scene_of(const SceneDocument& document);

/// Number of triangles in the input scene (instances counted).
uint64_t triangle_count(const SceneDocument& document);

/// Pixels of the decoded texture images (each holds 4 bytes in memory).
uint64_t image_pixel_count(const SceneDocument& document);

/// Empty when the scene can be baked; otherwise why not, for the user (no surface emits light, so
/// the bake would be black). A loaded scene may still be read without light (tests, inspection).
std::string bake_error(const SceneDocument& document);

/// Output settings.
struct WriteOptions {
  bool draco = true;        ///< KHR_draco_mesh_compression; false writes plain accessors
  int position_bits = 14;   ///< Draco quantization bits (0 = lossless)
  int texcoord_bits = 12;
  int color_bits = 10;
  int encode_speed = 5;     ///< Draco speed options, 0 (best compression) to 10 (fastest)
  int decode_speed = 5;
  double exposure = 0.0;    ///< COLOR_0's linear scale of light below the knee; 0 chooses one
  Tone tone = Tone::kShoulder;  ///< what happens above the knee (see ToneCurve)
};

struct WriteResult {
  std::vector<uint8_t> glb;  ///< empty on error
  std::string error;
  double exposure = 0.0;     ///< the exposure used
  ToneCurve tone;            ///< the curve used, with the white point chosen from the scene
};

/// Writes the baked scene: the input's nodes, names, materials, textures and UVs, each mesh
/// instance replaced by its radiosity mesh (crack-free triangles over the solver's elements),
/// COLOR_0 = the tone curve's map of exposure * radiosity / base colour, in [0, 1] (materials get
/// KHR_materials_unlit, so base colour x COLOR_0 shows the light; below the knee it is exactly
/// exposure x radiosity), _RADIOSITY = linear radiosity per vertex, and the method, parameters,
/// statistics, exposure and the curve's knee, white point and scale in asset.extras.hemibake. The
/// white point is the exposed light (mean of the channels) of the brightest vertex on a surface that
/// does not emit. `mesh` must come from a solve of scene_of(document).
WriteResult write_baked_glb(const SceneDocument& document, const solver::Mesh& mesh, Method method,
                            const solver::Params& params, const solver::Stats& stats,
                            const WriteOptions& options = {});

/// Reads a baked file (this writer's, or any glTF with POSITION and _RADIOSITY or COLOR_0) into a
/// mesh of triangles in world space with per-vertex radiosity, for rendering. Returns an empty
/// string or an error message.
std::string read_baked_mesh(const std::string& path, solver::Mesh& out);

}  // namespace hemibake::protocol
