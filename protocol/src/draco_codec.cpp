#include "draco_codec.h"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

namespace hemibake::protocol {
namespace {

template <typename T>
int add_attribute(draco::Mesh& mesh, draco::GeometryAttribute::Type type, int components, draco::DataType dt,
                  bool normalized, const std::vector<T>& values) {
  draco::GeometryAttribute ga;
  ga.Init(type, nullptr, static_cast<int8_t>(components), dt, normalized, sizeof(T) * components, 0);
  const size_t n = values.size() / components;
  const int id = mesh.AddAttribute(ga, true, static_cast<uint32_t>(n));
  draco::PointAttribute* att = mesh.attribute(id);
  for (size_t i = 0; i < n; ++i)
    att->SetAttributeValue(draco::AttributeValueIndex(static_cast<uint32_t>(i)), &values[i * components]);
  return id;
}

template <typename T>
bool read_attribute(const draco::Mesh& mesh, int unique_id, int components, std::vector<T>& out) {
  out.clear();
  if (unique_id < 0) return true;
  const draco::PointAttribute* att = mesh.GetAttributeByUniqueId(static_cast<uint32_t>(unique_id));
  if (!att || att->num_components() != components) return false;
  out.resize(static_cast<size_t>(mesh.num_points()) * components);
  for (draco::PointIndex p(0); p < mesh.num_points(); ++p) {
    if (!att->ConvertValue<T>(att->mapped_index(p), components, &out[static_cast<size_t>(p.value()) * components]))
      return false;
  }
  return true;
}

}  // namespace

std::string draco_encode(const PrimitiveData& data, const DracoSettings& settings, DracoEncoded& out) {
  draco::Mesh mesh;
  const size_t n = data.vertex_count();
  mesh.set_num_points(static_cast<uint32_t>(n));
  const size_t faces = data.indices.size() / 3;
  for (size_t f = 0; f < faces; ++f) {
    mesh.AddFace({draco::PointIndex(data.indices[3 * f]), draco::PointIndex(data.indices[3 * f + 1]),
                  draco::PointIndex(data.indices[3 * f + 2])});
  }
  const int pos = add_attribute(mesh, draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, data.positions);
  int uv = -1;
  if (!data.texcoords.empty())
    uv = add_attribute(mesh, draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32, false, data.texcoords);
  const int col = add_attribute(mesh, draco::GeometryAttribute::COLOR, 3, draco::DT_UINT16, true, data.colors);
  const int rad = add_attribute(mesh, draco::GeometryAttribute::GENERIC, 3, draco::DT_FLOAT32, false, data.radiosity);
  out.position_id = static_cast<int>(mesh.attribute(pos)->unique_id());
  out.texcoord_id = uv >= 0 ? static_cast<int>(mesh.attribute(uv)->unique_id()) : -1;
  out.color_id = static_cast<int>(mesh.attribute(col)->unique_id());
  out.radiosity_id = static_cast<int>(mesh.attribute(rad)->unique_id());

  draco::Encoder encoder;
  if (settings.position_bits > 0 && settings.position_range > 0.0f)
    encoder.SetAttributeExplicitQuantization(draco::GeometryAttribute::POSITION, settings.position_bits, 3,
                                             settings.position_origin.data(), settings.position_range);
  else if (settings.position_bits > 0)
    encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, settings.position_bits);
  if (settings.texcoord_bits > 0) encoder.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD, settings.texcoord_bits);
  encoder.SetSpeedOptions(settings.encode_speed, settings.decode_speed);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(mesh, &buffer);
  if (!status.ok()) return std::string("Draco encoding failed: ") + status.error_msg();
  out.bytes.assign(buffer.data(), buffer.data() + buffer.size());
  return draco_decode(out.bytes.data(), out.bytes.size(), out.position_id, out.texcoord_id, out.color_id,
                      out.radiosity_id, out.decoded);
}

std::string draco_decode(const uint8_t* bytes, size_t size, int position_id, int texcoord_id, int color_id,
                         int radiosity_id, PrimitiveData& out) {
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(bytes), size);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) return std::string("Draco decoding failed: ") + decoded.status().error_msg();
  const draco::Mesh& mesh = *decoded.value();
  if (!read_attribute(mesh, position_id, 3, out.positions) || !read_attribute(mesh, texcoord_id, 2, out.texcoords) ||
      !read_attribute(mesh, color_id, 3, out.colors) || !read_attribute(mesh, radiosity_id, 3, out.radiosity))
    return "the Draco mesh lacks an expected attribute";
  out.indices.resize(static_cast<size_t>(mesh.num_faces()) * 3);
  for (draco::FaceIndex f(0); f < mesh.num_faces(); ++f) {
    const auto& face = mesh.face(f);
    for (int k = 0; k < 3; ++k) out.indices[static_cast<size_t>(f.value()) * 3 + k] = face[k].value();
  }
  return {};
}

}  // namespace hemibake::protocol
