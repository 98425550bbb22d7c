// The `hemibake` command line; everything it does is in the client library (hemibake/client/cli.h).
#include "hemibake/client/cli.h"

#include <cstdio>

int main(int argc, char** argv) {
  // Lines as they happen, also into a pipe or a log file (a long bake's first lines would
  // otherwise wait in the buffer until it ends).
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  return hemibake::client::run_main(argc, argv);
}
