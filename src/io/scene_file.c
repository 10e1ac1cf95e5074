/* PLACEHOLDER: being written; replaced wholesale. */
#include "scene_file.h"
#include <string.h>
int ef_scene_file_read(const char *path, ef_scene_file *out, ef_err *err)
{
    memset(out, 0, sizeof *out);
    return ef_fail(err, "%s: not yet", path);
}
void ef_scene_file_free(ef_scene_file *f) { (void) f; }
int ef_read_text_file(const char *path, char **text, ef_err *err)
{
    *text = NULL;
    err->file = path;
    return ef_fail(err, "not yet");
}
