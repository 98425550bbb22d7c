// The one translation unit that compiles tinygltf and stb_image. Draco is decoded by the
// project's own code after tinygltf has parsed the file (gltf_parse.cpp).
#define TINYGLTF_IMPLEMENTATION
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <tiny_gltf.h>
