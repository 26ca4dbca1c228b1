// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
/* Minimal TCG plugin for qemu-user 7.2: counts executed guest instructions and
 * prints "insns: N" at exit (stderr, through qemu_plugin_outs). Built for the
 * HOST (it is loaded into the qemu-aarch64 process):
 *   cc -O2 -shared -fPIC -o qemu_insn_count.so tests/bench/qemu_insn_count.c
 * Used by tests/bench/insn_counts.sh (make bench-cross).
 *
 * Debian ships no qemu-plugin.h, so the few API items used here are declared
 * below by hand. They are the QEMU 7.2 plugin ABI facts (plugin API version 1),
 * checked against include/qemu/qemu-plugin.h, plugins/loader.c and
 * tests/plugin/insn.c of qemu/qemu and against the symbols that
 * /usr/bin/qemu-aarch64 (7.2) exports (nm -D):
 *   - the plugin exports an int named qemu_plugin_version; the loader refuses a
 *     plugin whose value is outside [QEMU_PLUGIN_MIN_VERSION, QEMU_PLUGIN_VERSION],
 *     and QEMU_PLUGIN_VERSION is 1 up to QEMU 8.x (2 from 9.0, when the inline
 *     registration below was replaced by per-vCPU variants);
 *   - plugin ids are 64-bit unsigned integers; TBs are opaque pointers;
 *   - the entry point is int qemu_plugin_install(id, const qemu_info_t *, argc, argv),
 *     returning 0 on success (we never read the info block, so it stays opaque);
 *   - the only inline operation is "add a 64-bit immediate to a uint64_t in
 *     memory", enumerator value 0 (the first of enum qemu_plugin_op);
 *   - an inline op registered on a TB at translation time runs every time that
 *     TB executes; qemu_plugin_tb_n_insns gives the TB's instruction count. */
#include <inttypes.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#define INSN_COUNT_EXPORT __attribute__((visibility("default")))

/* ---- QEMU 7.2 plugin ABI (our own declarations) ---- */
typedef uint64_t plugin_id;             /* qemu_plugin_id_t */
struct qemu_plugin_tb;                  /* opaque translation block */
typedef struct qemu_info_t qemu_info_t; /* opaque here: not read */
enum inline_op { INLINE_ADD_U64 = 0 };  /* enum qemu_plugin_op, QEMU_PLUGIN_INLINE_ADD_U64 */
typedef void (*tb_trans_cb)(plugin_id id, struct qemu_plugin_tb* tb); /* qemu_plugin_vcpu_tb_trans_cb_t */
typedef void (*udata_cb)(plugin_id id, void* userdata);               /* qemu_plugin_udata_cb_t */

void qemu_plugin_register_vcpu_tb_trans_cb(plugin_id id, tb_trans_cb cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb* tb);
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb* tb, enum inline_op op, void* ptr, uint64_t imm);
void qemu_plugin_register_atexit_cb(plugin_id id, udata_cb cb, void* userdata);
void qemu_plugin_outs(const char* string);

INSN_COUNT_EXPORT int qemu_plugin_version = 1; /* QEMU_PLUGIN_VERSION of 7.2 */
INSN_COUNT_EXPORT int qemu_plugin_install(plugin_id id, const qemu_info_t* info, int argc, char** argv);
/* ---- end of the ABI declarations ---- */

/* One counter: the guest is single-threaded (the benchmark uses one core), so
 * the non-atomic inline add is exact. */
static uint64_t executed;

static void on_translate(plugin_id id, struct qemu_plugin_tb* tb) {
  (void)id;
  qemu_plugin_register_vcpu_tb_exec_inline(tb, INLINE_ADD_U64, &executed, (uint64_t)qemu_plugin_tb_n_insns(tb));
}

static void on_exit_report(plugin_id id, void* userdata) {
  (void)id;
  (void)userdata;
  char line[64];
  snprintf(line, sizeof line, "insns: %" PRIu64 "\n", executed);
  qemu_plugin_outs(line);
}

int qemu_plugin_install(plugin_id id, const qemu_info_t* info, int argc, char** argv) {
  (void)info;
  (void)argv;
  if (argc != 0) return 1; /* takes no options */
  qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
  qemu_plugin_register_atexit_cb(id, on_exit_report, NULL);
  return 0;
}
