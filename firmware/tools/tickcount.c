/* QEMU TCG plugin (API v1, QEMU 7.2): exact instructions per tick of the `fil` board,
   the fake chips excluded. Counts, between each execution of the tick_begin marker and the
   next tick_end marker, the instructions of every translation block executed outside
   fake_enter .. fake_exit (the shims of paragyro_firmware::fil; the four markers' own
   blocks are not counted). Writes one decimal count per tick to out=PATH at exit.
   Arguments: begin=ADDR,end=ADDR,fin=ADDR,fout=ADDR (hex, Thumb bit cleared),out=PATH,
   and optionally hist=PATH: the counted instructions by translation block, as
   "address count" lines (a block's instructions at its start address; a block never spans
   two functions), for firmware/scripts/fil-profile.sh's split per stage; with only=K the
   histogram holds tick K (0-based) alone.
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

enum { K_PLAIN = 0, K_BEGIN = 1, K_END = 2, K_FIN = 3, K_FOUT = 4 };
/* one per translated block (a block translated twice gets two; summed by address) */
struct block { uint64_t pc, n, kind, counted; struct block *next; };
static struct block *blocks;
static char hist_path[512];
static long long hist_only = -1; /* only=K: the histogram of tick K alone */

static void tb_exec(unsigned int vcpu, void *udata) {
    struct block *b = udata;
    uint64_t n = b->n;
    switch (b->kind) {
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
        if (in_tick && !in_fake) {
            count += n;
            if (hist_only < 0 || (long long)n_ticks == hist_only) b->counted += n;
        }
    }
}

static void tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    uint64_t pc = qemu_plugin_tb_vaddr(tb);
    uint64_t n = qemu_plugin_tb_n_insns(tb);
    uint64_t k = pc == a_begin ? K_BEGIN : pc == a_end ? K_END : pc == a_fin ? K_FIN
               : pc == a_fout ? K_FOUT : K_PLAIN;
    struct block *b = calloc(1, sizeof *b);
    if (!b) { qemu_plugin_outs("tickcount: out of memory\n"); exit(3); }
    b->pc = pc; b->n = n; b->kind = k; b->next = blocks; blocks = b;
    qemu_plugin_register_vcpu_tb_exec_cb(tb, tb_exec, QEMU_PLUGIN_CB_NO_REGS, b);
}

static void at_exit(qemu_plugin_id_t id, void *p) {
    FILE *f = fopen(out_path, "w");
    char buf[700];
    if (!f) { qemu_plugin_outs("tickcount: cannot open the output file\n"); return; }
    for (size_t i = 0; i < n_ticks; i++) fprintf(f, "%llu\n", (unsigned long long)ticks[i]);
    fclose(f);
    if (hist_path[0]) {
        FILE *h = fopen(hist_path, "w");
        if (h) {
            for (struct block *b = blocks; b; b = b->next)
                if (b->counted) fprintf(h, "%llx %llu\n", (unsigned long long)b->pc, (unsigned long long)b->counted);
            fclose(h);
        }
    }
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
        else if (!strncmp(a, "hist=", 5)) snprintf(hist_path, sizeof hist_path, "%s", a + 5);
        else if (!strncmp(a, "only=", 5)) hist_only = strtoll(a + 5, NULL, 10);
    }
    if (!a_begin || !a_end || !a_fin || !a_fout) {
        qemu_plugin_outs("tickcount: begin=, end=, fin=, fout= are required\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, tb_trans);
    qemu_plugin_register_atexit_cb(id, at_exit, NULL);
    return 0;
}
