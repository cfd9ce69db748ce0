/*
 * Binary portability of the Linux x86_64 FMU: it loads on glibc 2.17 and newer (Debian 8,
 * Ubuntu 14.04, RHEL 7 and later), not only on the glibc it was built with.
 *
 * A newer glibc gives some functions a new symbol version, and a binary linked against it
 * needs that version at load time: exp, log and pow (GLIBC_2.29, the same computation without
 * the old SVID error handling), hypot (GLIBC_2.35) and stat (GLIBC_2.33, before it a wrapper
 * of __xstat).  Every newer glibc still exports the old versions, so the FMU binds to those:
 * the results are the same computation for every finite argument the model passes.  exp and
 * log, called a dozen times an internal step, and atan2 and asin, three times a communication
 * step for the outputs' attitude, bind to __exp_finite, __log_finite, __atan2_finite and
 * __asin_finite (GLIBC_2.15): the same computation without the wrapper of the functions'
 * default versions, which checks the arguments or the result for the SVID error handling
 * (about 20 instructions a call; the model builds with -fno-math-errno and reads no errno, and
 * its asin's argument is clamped to [-1, 1]).
 *
 * The build force-includes this header in every source of the FMU (CMakeLists.txt); elsewhere
 * (another C library, another processor, Windows) it does nothing.
 */
#ifndef JUNO_GLIBC_COMPAT_H
#define JUNO_GLIBC_COMPAT_H

#if defined(__linux__) && defined(__x86_64__) && !defined(JUNO_NO_GLIBC_COMPAT)
#include <features.h>
#if defined(__GLIBC__)
__asm__(".symver exp,__exp_finite@GLIBC_2.15");
__asm__(".symver log,__log_finite@GLIBC_2.15");
__asm__(".symver atan2,__atan2_finite@GLIBC_2.15");
__asm__(".symver asin,__asin_finite@GLIBC_2.15");
__asm__(".symver pow,pow@GLIBC_2.2.5");
__asm__(".symver hypot,hypot@GLIBC_2.2.5");

#include <sys/stat.h>
/* stat() as glibc before 2.33 compiled it: __xstat with the x86_64 kernel stat layout (1). */
extern int __xstat(int version, const char *path, struct stat *buf);
__asm__(".symver __xstat,__xstat@GLIBC_2.2.5");
#define stat(path, buf) __xstat(1, (path), (buf))
#endif
#endif

#endif
