/* The fuzz targets' private file: data written to DIR/name in a fresh
 * mkdtemp directory (so a reader that resolves names relative to the file,
 * or picks the format by extension, sees a real path). */
#ifndef FUZZ_FILE_H
#define FUZZ_FILE_H

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

/* Writes the file; 0 with path (and dir, to pass to fuzz_file_drop), or -1. */
static int fuzz_file_make(char dir[], const char *name, const void *data, size_t size,
                          char *path, size_t len)
{
    if (!mkdtemp(dir))
        return -1;
    snprintf(path, len, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    const int ok = f && (size == 0 || fwrite(data, 1, size, f) == size);
    if (f)
        fclose(f);
    if (!ok) {
        unlink(path);
        rmdir(dir);
        return -1;
    }
    return 0;
}

/* Removes the file and its directory. */
static void fuzz_file_drop(const char *dir, const char *path)
{
    unlink(path);
    rmdir(dir);
}

#endif
