#pragma once
/// @brief The `caps` subcommands. Each registers itself on the app and returns the action to run
/// after parsing; tools/ only parses, calls one library function and prints the result.

#include <CLI/CLI.hpp>
#include <functional>
#include <string>

namespace caps::cli {

/// Options every subcommand has.
struct Common {
  bool json = false;
  bool quiet = false;
  bool force = false;
};

using Action = std::function<void()>;

void add_phantom(CLI::App& app, Common& common, Action& action);
void add_model(CLI::App& app, Common& common, Action& action);
void add_volume(CLI::App& app, Common& common, Action& action);
void add_solve(CLI::App& app, Common& common, Action& action);
void add_plan(CLI::App& app, Common& common, Action& action);
void add_mesh(CLI::App& app, Common& common, Action& action);
void add_render(CLI::App& app, Common& common, Action& action);
void add_compare(CLI::App& app, Common& common, Action& action);
/// `caps model from-scan` and `caps model pick` (tools/cmd_scan.cpp), added to the model command.
void add_model_scan(CLI::App* model, Common& common, Action& action);

/// Adds --json and --quiet (and --force when `writes`) to a subcommand.
void add_common_flags(CLI::App* cmd, Common& common, bool writes);

/// Parses "a,b,c" into three doubles; throws caps::InvalidInput naming the option.
std::array<double, 3> parse_triple(const std::string& text, const std::string& option);

}  // namespace caps::cli
