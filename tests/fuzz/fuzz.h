/* fuzz.h: what the fuzz targets share -- libFuzzer's entry point, scratch files for
 * the readers that take a path, and the error contract every target checks.
 *
 * Each target is built twice: with libFuzzer (MCPOST_FUZZ=ON, clang) to search, and
 * with replay.c's main() in the ordinary test build, which feeds it the committed seed
 * and regression corpora, so that gcc and the ASan build run the same entry points. */
#ifndef MCP_FUZZ_H
#define MCP_FUZZ_H

#include <mcpost/error.h>
#include <mcpost/image.h>

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
/* fuzz_support.c: the settings every target runs under (quiet, a lower image
 * ceiling); libFuzzer calls it before the first input, replay.c's main() too. */
int LLVMFuzzerInitialize(int *argc, char ***argv);

/* A private scratch folder for this process (in /dev/shm when it exists, so that no
 * input touches a disk), created on first use; aborts when it cannot be made. */
const char *mcp_fuzz_dir(void);

/* Writes data to <mcp_fuzz_dir()>/<name> and returns that path (static storage,
 * one per slot 0..7); aborts on failure. */
const char *mcp_fuzz_file(int slot, const char *name, const void *data, size_t size);

/* The error contract (docs/library.md): a failed call returns -1 with one non-empty line
 * set; aborts (a finding) otherwise. rc is the call's return value. */
void mcp_fuzz_check_error(int rc, const char *what);

/* The bytes written as a file and read with mcp_image_read must give what reading them
 * from memory gave (rc, img): both an error, or the same pixels; aborts otherwise. */
void mcp_fuzz_same_as_file(int rc, const mcp_image *img, const void *data, size_t size,
                           const char *name);

#endif
