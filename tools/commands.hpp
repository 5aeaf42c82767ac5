#pragma once
/// @brief The `caps` subcommands: app's verbs (caps/app/verbs.hpp) and `serve`. Each binds its
/// options to a request (the fields the request declares: names, help and defaults come from
/// app/), calls its run function with the console reporter, and prints the result (--json: the
/// result's JSON on stdout).

#include <CLI/CLI.hpp>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "caps/app/console_reporter.hpp"
#include "caps/app/fields.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/run_guard.hpp"

namespace caps::cli {

/// Options every subcommand has (besides the request's own).
struct Common {
  bool json = false;
  bool quiet = false;
  std::vector<std::string> notes;  ///< e.g. an old option spelling that was used
};

using Action = std::function<void()>;

/// Binds a request's fields to a CLI11 subcommand.
class Binder {
 public:
  Binder(CLI::App* cmd, Common& common) : cmd_(cmd), common_(common) {}

  template <class T>
  void operator()(T& value, const app::Field& f) {
    const std::string name = f.cli.empty() ? "--" + app::dashed(f.key) : std::string(f.cli);
    const std::string help(f.help);
    CLI::Option* o = nullptr;
    if constexpr (std::is_same_v<T, bool>) {
      o = cmd_->add_flag(name, value, help);
    } else if constexpr (std::is_same_v<T, std::optional<double>>) {
      o = cmd_->add_option_function<double>(name, [&value](double x) { value = x; }, help);
    } else if constexpr (std::is_same_v<T, std::map<std::string, double>>) {
      for (const std::string& key : app::template_parameter_names())
        cmd_->add_option_function<double>(
            "--" + app::dashed(key), [&value, key](double x) { value[key] = x; }, help);
      return;
    } else {
      o = cmd_->add_option(name, value, help);
      if (f.kind == app::FieldKind::Option) o->capture_default_str();
    }
    if (f.kind == app::FieldKind::Required || f.kind == app::FieldKind::Positional) o->required();
    if constexpr (!std::is_same_v<T, bool> && !std::is_same_v<T, std::optional<double>>) {
      if (f.old_cli.empty()) return;
      const std::string old(f.old_cli), now = app::option_name(f);
      auto& notes = common_.notes;
      cmd_->add_option_function<T>(
              old,
              [&value, &notes, old, now](const T& x) {
                value = x;
                notes.push_back(cat(old, " is now ", now, "; the old spelling still works"));
              },
              help)
          ->group("");
    }
  }

 private:
  CLI::App* cmd_;
  Common& common_;
};

enum class Print { Stderr, Stdout };

/// Adds a subcommand `name` that fills a Request, runs `run` and prints its result: the JSON on
/// stdout with --json, else the summary (on stderr unless `print` is Stdout; nothing if quiet).
template <class Request, class Result>
CLI::App* add_verb(CLI::App* parent, const std::string& name, const std::string& description,
                   Result (*run)(const Request&, Reporter*), Common& common, Action& action,
                   Print print = Print::Stderr) {
  CLI::App* cmd = parent->add_subcommand(name, description);
  auto request = std::make_shared<Request>();
  Request::fields(*request, Binder(cmd, common));
  cmd->add_flag("--json", common.json, "print the result as JSON on stdout");
  cmd->add_flag("-q,--quiet", common.quiet, "no progress bar or messages on stderr");
  cmd->callback([&common, &action, request, run, print] {
    action = [&common, request, run, print] {
      // Ctrl-C or a kill removes what this run had begun to write; its output is its own until
      // it ends (a second run writing it is refused).
      const app::InterruptCleanup interrupt;
      const auto claim = app::claim_output(*request);
      app::ConsoleReporter reporter(common.quiet);
      for (const std::string& n : common.notes) reporter.note(n);
      const Result result = run(*request, &reporter);
      if (common.json) {
        std::cout << to_json(result) << "\n";
      } else if (print == Print::Stdout) {
        std::cout << summary(result) << "\n";
      } else if (!common.quiet) {
        std::cerr << summary(result) << "\n";
      }
    };
  });
  return cmd;
}

/// Every verb of app's list (caps/app/verbs.hpp), in its order, grouped by its first word
/// ("model from-volume" under "model").
void add_verbs(CLI::App& app, Common& common, Action& action);
void add_serve(CLI::App& app, Common& common, Action& action);

}  // namespace caps::cli
