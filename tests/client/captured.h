// A Console whose two streams are read back as text, for the client's tests.
#pragma once

#include "hemibake/client/console.h"

#include <cstdio>
#include <cstdlib>
#include <string>

namespace hemibake::client {

struct Captured {
  char* out_text = nullptr;
  char* err_text = nullptr;
  size_t out_size = 0, err_size = 0;
  Console console;
  Captured() {
    console.out = open_memstream(&out_text, &out_size);
    console.err = open_memstream(&err_text, &err_size);
  }
  ~Captured() {
    close();
    std::free(out_text);
    std::free(err_text);
  }
  Captured(const Captured&) = delete;
  Captured& operator=(const Captured&) = delete;
  void close() {
    if (console.out) std::fclose(console.out);
    if (console.err) std::fclose(console.err);
    console.out = console.err = nullptr;
  }
  std::string out() {
    std::fflush(console.out);
    return std::string(out_text, out_size);
  }
  std::string err() {
    std::fflush(console.err);
    return std::string(err_text, err_size);
  }
};

}  // namespace hemibake::client
