// libFuzzer target: multipart/form-data bodies. The input is a boundary, a newline, and the body.
// Every part found must be a piece of the body.
#include "hemibake/server/service.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const size_t newline = input.find('\n');
  if (newline == std::string::npos) return 0;
  const std::string boundary = input.substr(0, newline), body = input.substr(newline + 1);
  std::string repeated;
  const auto parts = hemibake::server::parse_multipart(body, boundary, repeated);
  for (const auto& [name, part] : parts)
    if (part.second.size() > body.size() || (!part.second.empty() && body.find(part.second) == std::string::npos)) std::abort();
  return 0;
}
