#pragma once
/// @brief A process that dies of a fault (SIGFPE, SIGSEGV, SIGBUS, SIGILL) says where first: the
/// signal and the call stack on stderr, then it dies of the same signal (the exit status a shell
/// or ctest reports is unchanged). For faults that cannot be reproduced at will (a SIGFPE seen
/// twice under a loaded test run and never alone): the next one leaves its stack in the log.
/// The caps program and the test programs install it; not under AddressSanitizer, which reports
/// faults itself.

namespace caps {

/// Installs the handlers (once; later calls do nothing).
void install_crash_report();

}  // namespace caps
