// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
/* TCG plugin for qemu-user 7.2: where a program's aarch64 instructions go.
 * Counts each translation block's executions and, at exit, prints the
 * instructions executed per function (the symbol of each block's first
 * instruction), most first, one "profile: N name" line each, then
 * "profile: N total" (the same total as qemu_insn_count.c). qemu has no
 * symbols for shared libraries: their blocks are named "[FILE]+0xOFFSET", the
 * file mapped there and the block's offset in it, for profile_frame.sh to
 * look up in the library's dynamic symbols. Built for the
 * HOST, like qemu_insn_count.c:
 *   cc -O2 -shared -fPIC -o qemu_tb_profile.so tests/bench/qemu_tb_profile.c
 *   qemu-aarch64 -plugin ./qemu_tb_profile.so -d plugin PROGRAM ARGS...
 * tests/bench/profile_frame.sh runs it on a scene profile's frames.
 *
 * The ABI items beyond qemu_insn_count.c's (declared by hand for the same
 * reason: Debian ships no qemu-plugin.h), as QEMU 7.2's include/qemu/qemu-plugin.h
 * gives them and /usr/bin/qemu-aarch64 exports them (nm -D):
 *   - qemu_plugin_tb_get_insn(tb, i) gives a TB's i-th instruction (opaque);
 *   - qemu_plugin_insn_symbol(insn) gives the name of the symbol it lies in, or
 *     NULL (qemu-user knows the symbols of the main executable only);
 *   - qemu_plugin_insn_haddr(insn) gives the host address qemu reads the
 *     instruction from: in qemu-user the guest's memory is the qemu process's,
 *     so /proc/self/maps names the file mapped there. */
#include <inttypes.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define TB_PROFILE_EXPORT __attribute__((visibility("default")))

/* ---- QEMU 7.2 plugin ABI (our own declarations) ---- */
typedef uint64_t plugin_id;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
typedef struct qemu_info_t qemu_info_t;
enum inline_op { INLINE_ADD_U64 = 0 };
typedef void (*tb_trans_cb)(plugin_id id, struct qemu_plugin_tb* tb);
typedef void (*udata_cb)(plugin_id id, void* userdata);

void qemu_plugin_register_vcpu_tb_trans_cb(plugin_id id, tb_trans_cb cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb* tb);
struct qemu_plugin_insn* qemu_plugin_tb_get_insn(const struct qemu_plugin_tb* tb, size_t idx);
const char* qemu_plugin_insn_symbol(const struct qemu_plugin_insn* insn);
void* qemu_plugin_insn_haddr(const struct qemu_plugin_insn* insn);
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb* tb, enum inline_op op, void* ptr, uint64_t imm);
void qemu_plugin_register_atexit_cb(plugin_id id, udata_cb cb, void* userdata);
void qemu_plugin_outs(const char* string);

TB_PROFILE_EXPORT int qemu_plugin_version = 1;
TB_PROFILE_EXPORT int qemu_plugin_install(plugin_id id, const qemu_info_t* info, int argc, char** argv);
/* ---- end of the ABI declarations ---- */

/* One record a translation (a block translated again gets another: they are
 * summed by name at exit). The guest is single-threaded, so the inline adds
 * are exact. Records live in fixed chunks: their addresses must not move. */
typedef struct {
  uint64_t executions;
  uint64_t insns;
  const char* symbol; /* NULL: resolved from host_address at exit */
  uintptr_t host_address;
} Block;

enum { kChunk = 4096 };
typedef struct Chunk {
  Block blocks[kChunk];
  size_t used;
  struct Chunk* next;
} Chunk;
static Chunk* chunks;
static int out_of_memory;

static Block* new_block(void) {
  if (chunks == NULL || chunks->used == kChunk) {
    Chunk* c = calloc(1, sizeof *c);
    if (c == NULL) return NULL;
    c->next = chunks;
    chunks = c;
  }
  return &chunks->blocks[chunks->used++];
}

static void on_translate(plugin_id id, struct qemu_plugin_tb* tb) {
  (void)id;
  const size_t n = qemu_plugin_tb_n_insns(tb);
  if (n == 0) return;
  Block* b = new_block();
  if (b == NULL) {
    out_of_memory = 1;
    return;
  }
  const struct qemu_plugin_insn* first = qemu_plugin_tb_get_insn(tb, 0);
  b->insns = n;
  b->symbol = qemu_plugin_insn_symbol(first);
  b->host_address = (uintptr_t)qemu_plugin_insn_haddr(first);
  qemu_plugin_register_vcpu_tb_exec_inline(tb, INLINE_ADD_U64, &b->executions, 1);
}

/* The file mapped at a host address (basename), from /proc/self/maps. */
typedef struct {
  uintptr_t lo, hi, offset;
  char path[256];
} Mapping;
static Mapping* maps;
static size_t n_maps;

static void read_maps(void) {
  FILE* f = fopen("/proc/self/maps", "r");
  if (f == NULL) return;
  char line[512];
  size_t cap = 0;
  while (fgets(line, sizeof line, f) != NULL) {
    unsigned long lo = 0, hi = 0, offset = 0;
    int path_at = 0;
    if (sscanf(line, "%lx-%lx %*s %lx %*s %*s %n", &lo, &hi, &offset, &path_at) < 3 || path_at == 0) continue;
    char* path = line + path_at;
    path[strcspn(path, "\n")] = '\0';
    if (path[0] == '\0') continue;
    if (n_maps == cap) {
      cap = cap ? 2 * cap : 64;
      Mapping* grown = realloc(maps, cap * sizeof *maps);
      if (grown == NULL) break;
      maps = grown;
    }
    Mapping* m = &maps[n_maps++];
    m->lo = lo;
    m->hi = hi;
    m->offset = offset;
    snprintf(m->path, sizeof m->path, "%s", path);
  }
  fclose(f);
}

/* "[FILE]+0xOFFSET" for a host address (a new string; NULL: out of memory). */
static char* mapped_name(uintptr_t address) {
  char name[320];
  snprintf(name, sizeof name, "[unmapped]");
  for (size_t i = 0; i < n_maps; ++i) {
    if (address >= maps[i].lo && address < maps[i].hi) {
      snprintf(name, sizeof name, "[%s]+0x%lx", maps[i].path, (unsigned long)(address - maps[i].lo + maps[i].offset));
      break;
    }
  }
  return strdup(name);
}

typedef struct {
  const char* name;
  uint64_t insns;
} Total;

static int by_insns_then_name(const void* a, const void* b) {
  const Total* x = a;
  const Total* y = b;
  if (x->insns != y->insns) return x->insns > y->insns ? -1 : 1;
  return strcmp(x->name, y->name);
}

static int by_name(const void* a, const void* b) { return strcmp(((const Total*)a)->name, ((const Total*)b)->name); }

static void on_exit_report(plugin_id id, void* userdata) {
  (void)id;
  (void)userdata;
  read_maps();
  size_t n = 0;
  for (const Chunk* c = chunks; c != NULL; c = c->next) n += c->used;
  Total* all = calloc(n ? n : 1, sizeof *all);
  if (all == NULL) {
    qemu_plugin_outs("profile: out of memory\n");
    return;
  }
  size_t k = 0;
  uint64_t total = 0;
  for (const Chunk* c = chunks; c != NULL; c = c->next) {
    for (size_t i = 0; i < c->used; ++i) {
      const Block* b = &c->blocks[i];
      all[k].name = b->symbol ? b->symbol : mapped_name(b->host_address);
      if (all[k].name == NULL) all[k].name = "[out of memory]";
      all[k].insns = b->executions * b->insns;
      total += all[k].insns;
      ++k;
    }
  }
  /* Sum by name, then sort by instructions. */
  qsort(all, k, sizeof *all, by_name);
  size_t m = 0;
  for (size_t i = 0; i < k; ++i) {
    if (m > 0 && strcmp(all[m - 1].name, all[i].name) == 0) {
      all[m - 1].insns += all[i].insns;
    } else {
      all[m++] = all[i];
    }
  }
  qsort(all, m, sizeof *all, by_insns_then_name);
  char line[2048]; /* (a name longer than the line is cut, the line kept whole) */
  for (size_t i = 0; i < m; ++i) {
    if (all[i].insns == 0) break;
    snprintf(line, sizeof line, "profile: %" PRIu64 " %.2000s\n", all[i].insns, all[i].name);
    qemu_plugin_outs(line);
  }
  snprintf(line, sizeof line, "profile: %" PRIu64 " total%s\n", total,
           out_of_memory ? " (blocks dropped: out of memory)" : "");
  qemu_plugin_outs(line);
  free(all);
}

int qemu_plugin_install(plugin_id id, const qemu_info_t* info, int argc, char** argv) {
  (void)info;
  (void)argv;
  if (argc != 0) return 1; /* takes no options */
  qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
  qemu_plugin_register_atexit_cb(id, on_exit_report, NULL);
  return 0;
}
