// Draco mesh encoding for KHR_draco_mesh_compression, and decoding for checks.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace hemibake::protocol {

/// One primitive's vertex data, interleaved per attribute.
struct PrimitiveData {
  std::vector<float> positions;     ///< 3 per vertex
  std::vector<float> texcoords;     ///< 2 per vertex, or empty
  std::vector<uint16_t> colors;     ///< 3 per vertex, normalized
  std::vector<float> radiosity;     ///< 3 per vertex
  std::vector<uint32_t> indices;    ///< 3 per triangle
  size_t vertex_count() const { return positions.size() / 3; }
};

/// The encoded bitstream, and the data as a decoder gives it back (Draco may reorder vertices, so
/// glTF's fallback accessors must describe the decoded data).
struct DracoEncoded {
  std::vector<uint8_t> bytes;
  int position_id = -1, texcoord_id = -1, color_id = -1, radiosity_id = -1;  ///< unique ids
  PrimitiveData decoded;
};

struct DracoSettings {
  int position_bits = 14;
  int texcoord_bits = 12;
  int encode_speed = 5;
  int decode_speed = 5;
  /// With position_range > 0, positions are quantized in the cube [origin, origin + range] (every
  /// position must lie in it), in steps of range / (2^position_bits - 1), instead of in the
  /// primitive's own bounding cube: primitives given one grid keep the points they share equal.
  std::array<float, 3> position_origin{};
  float position_range = 0.0f;
};

/// Encodes `data`; returns an error message, or an empty string on success.
std::string draco_encode(const PrimitiveData& data, const DracoSettings& settings, DracoEncoded& out);

/// Decodes a Draco mesh bitstream with attributes of the given unique ids (-1: absent).
std::string draco_decode(const uint8_t* bytes, size_t size, int position_id, int texcoord_id, int color_id,
                         int radiosity_id, PrimitiveData& out);

}  // namespace hemibake::protocol
