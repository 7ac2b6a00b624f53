/* QEMU TCG plugin (API v1, QEMU 7.2): an exact per-address instruction histogram of the
   code in flash [0x08000000, 0x08100000), written at exit to the file given as out=PATH as
   "address count" lines (hex address, decimal count, non-zero only), plus the total.
   Derived from shared/tools/qemu-insncount/insncount.c (same hand-declared v1 API).
   Build: gcc -shared -fPIC -O2 -o libinsnprof.so insnprof.c
   Use:   qemu-system-arm ... -plugin ./libinsnprof.so,out=/tmp/prof.txt -d plugin
   firmware/scripts/fw-profile.sh maps the addresses to functions (llvm-nm) and groups them. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stdbool.h>
typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb; struct qemu_plugin_insn; typedef struct qemu_info_t qemu_info_t;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
extern size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
extern struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
extern uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
extern void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn, enum qemu_plugin_op op, void *ptr, uint64_t imm);
extern void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb *tb, enum qemu_plugin_op op, void *ptr, uint64_t imm);
extern void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
extern void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
extern void qemu_plugin_outs(const char *string);
__attribute__((visibility("default"))) int qemu_plugin_version = 1;
#define BASE 0x08000000ull
#define SIZE 0x00100000ull
static uint64_t total, outside;
static uint64_t hist[SIZE / 2];
static char out_path[512] = "insnprof.txt";
static void tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    size_t n = qemu_plugin_tb_n_insns(tb);
    qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &total, n);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        uint64_t *slot = (pc >= BASE && pc < BASE + SIZE) ? &hist[(pc - BASE) / 2] : &outside;
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, slot, 1);
    }
}
static void at_exit(qemu_plugin_id_t id, void *p) {
    FILE *f = fopen(out_path, "w");
    char buf[160];
    if (!f) {
        qemu_plugin_outs("insnprof: cannot open the output file\n");
        return;
    }
    fprintf(f, "# total %llu outside-flash %llu\n", (unsigned long long)total, (unsigned long long)outside);
    for (uint64_t i = 0; i < SIZE / 2; i++)
        if (hist[i]) fprintf(f, "%llx %llu\n", (unsigned long long)(BASE + 2 * i), (unsigned long long)hist[i]);
    fclose(f);
    snprintf(buf, sizeof buf, "insnprof: total=%llu written to %s\n", (unsigned long long)total, out_path);
    qemu_plugin_outs(buf);
}
__attribute__((visibility("default")))
int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv) {
    for (int i = 0; i < argc; i++)
        if (!strncmp(argv[i], "out=", 4)) snprintf(out_path, sizeof out_path, "%s", argv[i] + 4);
    qemu_plugin_register_vcpu_tb_trans_cb(id, tb_trans);
    qemu_plugin_register_atexit_cb(id, at_exit, NULL);
    return 0;
}
