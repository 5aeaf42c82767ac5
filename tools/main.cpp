// caps: computer-aided plastic surgery planning, command line.
//   caps --help
//   caps phantom -o /tmp/ct.nii.gz
//   caps model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o /tmp/cranium
//   caps model info /tmp/cranium
// Exit codes: 0 success, 2 bad input (message names the file or field), 1 a failed solve
// (message names the element, Gauss point or iteration) or another error.
#include <cstdio>
#include <exception>

#include "caps/core/error.hpp"
#include "caps/core/progress.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_common_flags(CLI::App* cmd, Common& common, bool writes) {
  cmd->add_flag("--json", common.json, "print a machine-readable summary on stdout");
  cmd->add_flag("-q,--quiet", common.quiet, "no progress bar or messages on stderr");
  if (writes) cmd->add_flag("--force", common.force, "replace an existing output");
}

std::array<double, 3> parse_triple(const std::string& text, const std::string& option) {
  std::array<double, 3> v{};
  char c1 = 0, c2 = 0;
  std::istringstream in(text);
  if (!(in >> v[0] >> c1 >> v[1] >> c2 >> v[2]) || c1 != ',' || c2 != ',' || !in.eof())
    throw InvalidInput(cat(option, " '", text, "': expected three numbers separated by commas, "
                           "e.g. ", option, " 1,1,1"));
  return v;
}

}  // namespace caps::cli

int main(int argc, char** argv) {
  using namespace caps;
  CLI::App app{"caps: computer-aided plastic surgery planning.\n"
               "Builds patient models from CT/MR and surface scans, plans incisions, simulates "
               "wound closure.\nExample: caps model from-volume Cranium.inv3 -o cranium"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "caps 0.1.0");
  cli::Common common;
  cli::Action action;
  cli::add_phantom(app, common, action);
  cli::add_model(app, common, action);
  cli::add_volume(app, common, action);
  cli::add_solve(app, common, action);
  cli::add_plan(app, common, action);
  cli::add_mesh(app, common, action);
  cli::add_render(app, common, action);
  cli::add_compare(app, common, action);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "caps: %s\nRun with --help for usage.\n", e.what());
    return 2;
  }
  set_quiet(common.quiet);
  try {
    if (action) action();
    return 0;
  } catch (const InvalidInput& e) {
    std::fprintf(stderr, "caps: error: %s\n", e.what());
    return 2;
  } catch (const IoError& e) {
    std::fprintf(stderr, "caps: error: %s\n", e.what());
    return 2;
  } catch (const SolverError& e) {
    std::fprintf(stderr, "caps: solver error: %s\n", e.what());
    return 1;
  } catch (const Error& e) {
    std::fprintf(stderr, "caps: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "caps: error: out of memory; the input may be larger than this machine "
                         "can hold\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "caps: internal error: %s\n", e.what());
    return 1;
  }
}
