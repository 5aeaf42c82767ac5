// caps: computer-aided plastic surgery planning, command line.
//   caps --help
//   caps phantom -o /tmp/ct.nii.gz
//   caps model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o /tmp/cranium
//   caps model info /tmp/cranium
//   caps serve /tmp/cranium
// Exit codes: 0 success, 2 bad input (message names the file or field), 1 internal error or a
// failed solve.
#include <cstdio>
#include <exception>

#include "caps/app/fields.hpp"
#include "caps/core/crash_report.hpp"
#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/fem/blas.hpp"
#include "commands.hpp"

int main(int argc, char** argv) {
  using namespace caps;
  // OpenBLAS chose its generic kernels on a CPU it does not know (fem/blas.hpp): the kernels the
  // CPU runs, before any BLAS work. The factorizations then take about half the time.
  fem::use_the_cpus_blas_kernels();
  install_crash_report();
  CLI::App app{"caps: computer-aided plastic surgery planning.\n"
               "Builds patient models from CT/MR and surface scans, plans incisions, simulates "
               "wound closure.\nExample: caps model from-volume Cranium.inv3 -o cranium",
               "caps"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "caps 0.1.0");
  cli::Common common;
  cli::Action action;
  cli::add_verbs(app, common, action);
  cli::add_serve(app, common, action);
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
  try {
    if (action) action();
    return 0;
  } catch (const InvalidParameter& e) {  // named as the user typed it: --apex-angle
    const std::string m =
        e.spelled([](const std::string& key) { return "--" + app::dashed(key); });
    std::fprintf(stderr, "caps: error: %s\n", m.c_str());
    return 2;
  } catch (const InvalidInput& e) {
    std::fprintf(stderr, "caps: error: %s\n", e.what());
    return 2;
  } catch (const IoError& e) {
    std::fprintf(stderr, "caps: error: %s\n", e.what());
    return 2;
  } catch (const SolverError& e) {
    std::fprintf(stderr, "caps: solver error: %s\n", e.what());
    return 1;
  } catch (const Cancelled& e) {
    std::fprintf(stderr, "caps: %s\n", e.what());
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
