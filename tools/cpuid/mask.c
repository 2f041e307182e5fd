/*
 * An LD_PRELOAD library that makes a process (and the programs it starts)
 * see an x86-64 CPU without AVX-512 and AVX-VNNI (avx2_only.so), or, built
 * with -DKEEP_AVX_VNNI, without AVX-512 but with AVX-VNNI (avx_vnni.so),
 * so that `cargo xtask ort-bench --avx2` (or `--avx-vnni`) times ONNX
 * Runtime and our kernels on the code paths both pick on such a CPU, on
 * the same machine.
 *
 * How: Linux's CPUID faulting (arch_prctl ARCH_SET_CPUID, on Intel CPUs
 * that have it: the `cpuid_fault` flag) makes every CPUID instruction of
 * the process raise SIGSEGV. The handler below allows CPUID for a moment,
 * runs it, clears the feature bits of AVX-512 (leaf 7: EBX, ECX, EDX) and
 * of AVX512-BF16 and (unless kept) AVX-VNNI (leaf 7, subleaf 1: EAX),
 * writes the
 * registers back and steps over the instruction. The dynamic loader's own
 * CPUID calls come before this library's constructor and see the real CPU
 * (glibc's string functions); every program's feature detection after
 * start-up (Rust's is_x86_feature_detected!, ONNX Runtime's MLAS, numpy)
 * sees the masked one. Without CPUID faulting the constructor stops the
 * process with a message rather than let it run unmasked.
 */
#define _GNU_SOURCE
#include <cpuid.h>
#include <signal.h>
#include <stdint.h>
#include <string.h>
#include <sys/syscall.h>
#include <ucontext.h>
#include <unistd.h>

#define ARCH_SET_CPUID 0x1012

static void on_fault(int sig, siginfo_t *info, void *context) {
    (void)sig;
    (void)info;
    ucontext_t *uc = context;
    greg_t *r = uc->uc_mcontext.gregs;
    const uint8_t *ip = (const uint8_t *)r[REG_RIP];
    if (ip[0] != 0x0f || ip[1] != 0xa2) {
        /* Not CPUID: a real fault, which the default action reports. */
        signal(SIGSEGV, SIG_DFL);
        return;
    }
    unsigned leaf = (unsigned)r[REG_RAX], sub = (unsigned)r[REG_RCX];
    unsigned a, b, c, d;
    syscall(SYS_arch_prctl, ARCH_SET_CPUID, 1);
    __cpuid_count(leaf, sub, a, b, c, d);
    syscall(SYS_arch_prctl, ARCH_SET_CPUID, 0);
    if (leaf == 7 && sub == 0) {
        /* AVX512 F, DQ, IFMA, PF, ER, CD, BW, VL */
        b &= ~(1u << 16 | 1u << 17 | 1u << 21 | 1u << 26 | 1u << 27 | 1u << 28 | 1u << 30 | 1u << 31);
        /* AVX512 VBMI, VBMI2, VNNI, BITALG, VPOPCNTDQ */
        c &= ~(1u << 1 | 1u << 6 | 1u << 11 | 1u << 12 | 1u << 14);
        /* AVX512 4VNNIW, 4FMAPS, VP2INTERSECT, FP16 */
        d &= ~(1u << 2 | 1u << 3 | 1u << 8 | 1u << 23);
    } else if (leaf == 7 && sub == 1) {
        /* AVX512 BF16, and AVX-VNNI unless kept */
        a &= ~(1u << 5);
#ifndef KEEP_AVX_VNNI
        a &= ~(1u << 4);
#endif
    }
    r[REG_RAX] = a;
    r[REG_RBX] = b;
    r[REG_RCX] = c;
    r[REG_RDX] = d;
    r[REG_RIP] += 2;
}

__attribute__((constructor)) static void mask_cpuid(void) {
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_sigaction = on_fault;
    sa.sa_flags = SA_SIGINFO | SA_NODEFER;
    if (sigaction(SIGSEGV, &sa, 0) != 0 || syscall(SYS_arch_prctl, ARCH_SET_CPUID, 0) != 0) {
        static const char msg[] =
            "avx2_only.so: this CPU or kernel has no CPUID faulting; cannot hide AVX-512\n";
        ssize_t ignored = write(2, msg, sizeof msg - 1);
        (void)ignored;
        _exit(3);
    }
}
