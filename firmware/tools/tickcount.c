/* QEMU TCG plugin (API v1, QEMU 7.2): exact instructions per tick of the `fil` board,
   the fake chips excluded. Counts, between each execution of the tick_begin marker and the
   next tick_end marker, the instructions of every translation block executed outside
   fake_enter .. fake_exit (the shims of paragyro_firmware::fil; the four markers' own
   blocks are not counted). Writes one decimal count per tick to out=PATH at exit.
   Arguments: begin=ADDR,end=ADDR,fin=ADDR,fout=ADDR (hex, Thumb bit cleared),out=PATH.
   Build: cc -shared -fPIC -O2 -o libtickcount.so tickcount.c
   Same hand-declared v1 API as insnprof.c (Debian's QEMU ships no qemu-plugin.h). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb; struct qemu_plugin_insn; typedef struct qemu_info_t qemu_info_t;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);
extern size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
extern uint64_t qemu_plugin_tb_vaddr(const struct qemu_plugin_tb *tb);
extern void qemu_plugin_register_vcpu_tb_exec_cb(struct qemu_plugin_tb *tb, qemu_plugin_vcpu_udata_cb_t cb, enum qemu_plugin_cb_flags flags, void *userdata);
extern void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
extern void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
extern void qemu_plugin_outs(const char *string);
__attribute__((visibility("default"))) int qemu_plugin_version = 1;

static uint64_t a_begin, a_end, a_fin, a_fout;
static int in_tick, in_fake;
static uint64_t count;
static uint64_t *ticks;
static size_t n_ticks, cap_ticks;
static char out_path[512] = "tickcount.txt";

/* udata: the block's instruction count in the low 32 bits, its kind in the high bits */
enum { K_PLAIN = 0, K_BEGIN = 1, K_END = 2, K_FIN = 3, K_FOUT = 4 };

static void tb_exec(unsigned int vcpu, void *udata) {
    uint64_t u = (uint64_t)(uintptr_t)udata;
    uint64_t n = u & 0xffffffffu;
    switch (u >> 32) {
    case K_BEGIN: in_tick = 1; in_fake = 0; count = 0; return;
    case K_END:
        if (in_tick) {
            if (n_ticks == cap_ticks) {
                cap_ticks = cap_ticks ? 2 * cap_ticks : 8192;
                ticks = realloc(ticks, cap_ticks * sizeof *ticks);
                if (!ticks) { qemu_plugin_outs("tickcount: out of memory\n"); exit(3); }
            }
            ticks[n_ticks++] = count;
        }
        in_tick = 0;
        return;
    case K_FIN: in_fake = 1; return;
    case K_FOUT: in_fake = 0; return;
    default:
        if (in_tick && !in_fake) count += n;
    }
}

static void tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    uint64_t pc = qemu_plugin_tb_vaddr(tb);
    uint64_t n = qemu_plugin_tb_n_insns(tb);
    uint64_t k = pc == a_begin ? K_BEGIN : pc == a_end ? K_END : pc == a_fin ? K_FIN
               : pc == a_fout ? K_FOUT : K_PLAIN;
    qemu_plugin_register_vcpu_tb_exec_cb(tb, tb_exec, QEMU_PLUGIN_CB_NO_REGS,
                                         (void *)(uintptr_t)((k << 32) | n));
}

static void at_exit(qemu_plugin_id_t id, void *p) {
    FILE *f = fopen(out_path, "w");
    char buf[700];
    if (!f) { qemu_plugin_outs("tickcount: cannot open the output file\n"); return; }
    for (size_t i = 0; i < n_ticks; i++) fprintf(f, "%llu\n", (unsigned long long)ticks[i]);
    fclose(f);
    snprintf(buf, sizeof buf, "tickcount: %zu ticks written to %s\n", n_ticks, out_path);
    qemu_plugin_outs(buf);
}

__attribute__((visibility("default")))
int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv) {
    for (int i = 0; i < argc; i++) {
        const char *a = argv[i];
        if (!strncmp(a, "out=", 4)) snprintf(out_path, sizeof out_path, "%s", a + 4);
        else if (!strncmp(a, "begin=", 6)) a_begin = strtoull(a + 6, NULL, 16);
        else if (!strncmp(a, "end=", 4)) a_end = strtoull(a + 4, NULL, 16);
        else if (!strncmp(a, "fin=", 4)) a_fin = strtoull(a + 4, NULL, 16);
        else if (!strncmp(a, "fout=", 5)) a_fout = strtoull(a + 5, NULL, 16);
    }
    if (!a_begin || !a_end || !a_fin || !a_fout) {
        qemu_plugin_outs("tickcount: begin=, end=, fin=, fout= are required\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, tb_trans);
    qemu_plugin_register_atexit_cb(id, at_exit, NULL);
    return 0;
}
