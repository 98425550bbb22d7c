// The commands that bake or render on this machine.
#pragma once

#include "hemibake/client/cli.h"

namespace hemibake::client {

int run_cornell(const CommandLine& command, const Console& console);
int run_room(const CommandLine& command, const Console& console);
int run_clutter(const CommandLine& command, const Console& console);
int run_lava(const CommandLine& command, const Console& console);
int run_atrium(const CommandLine& command, const Console& console);
int run_render(const CommandLine& command, const Console& console);
int run_bake(const CommandLine& command, const Console& console);

}  // namespace hemibake::client
