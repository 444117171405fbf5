/* report.c: the run report -- JSON document and HTML page (see report.h). */
#include <mcpost/report.h>
#include <mcpost/imageio.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct mcp_report {
    cJSON *root;
};

int
mcp_report_new(const char *title, mcp_report **out)
{
    mcp_report *r = mcp_calloc(1, sizeof *r);
    if (!r)
        return -1;
    r->root = cJSON_CreateObject();
    if (!r->root || !cJSON_AddStringToObject(r->root, "title", title) ||
        !cJSON_AddArrayToObject(r->root, "sections")) {
        mcp_report_free(r);
        return mcp_error("out of memory for the report");
    }
    *out = r;
    return 0;
}

void
mcp_report_free(mcp_report *r)
{
    if (!r)
        return;
    cJSON_Delete(r->root);
    free(r);
}

cJSON *
mcp_report_json(mcp_report *r)
{
    return r->root;
}

cJSON *
mcp_report_section(mcp_report *r, const char *stage, const char *title)
{
    cJSON *s = cJSON_CreateObject();
    if (!s || !cJSON_AddStringToObject(s, "stage", stage) ||
        !cJSON_AddStringToObject(s, "title", title)) {
        cJSON_Delete(s);
        mcp_error("out of memory for the report");
        return NULL;
    }
    cJSON_AddItemToArray(cJSON_GetObjectItem(r->root, "sections"), s);
    return s;
}

int
mcp_report_add_image(cJSON *section, const char *rel_path, const char *caption)
{
    cJSON *images = cJSON_GetObjectItem(section, "images");
    if (!images && !(images = cJSON_AddArrayToObject(section, "images")))
        return mcp_error("out of memory for the report");
    cJSON *img = cJSON_CreateObject();
    if (!img || !cJSON_AddStringToObject(img, "path", rel_path) ||
        !cJSON_AddStringToObject(img, "caption", caption ? caption : "")) {
        cJSON_Delete(img);
        return mcp_error("out of memory for the report");
    }
    cJSON_AddItemToArray(images, img);
    return 0;
}

static int
write_text(const char *dir, const char *name, const char *text)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    return mcp_write_file_atomic(path, text, strlen(text));
}

/* A minimal page until the HTML writer lands: the JSON, readable. */
static char *
html_page(mcp_report *r)
{
    char *json = cJSON_Print(r->root);
    if (!json)
        return NULL;
    const char *title = cJSON_GetObjectItem(r->root, "title")->valuestring;
    size_t n = strlen(json) * 6 + strlen(title) + 256;
    char *page = malloc(n), *p = page;
    if (!page) {
        free(json);
        return NULL;
    }
    p += sprintf(p, "<!doctype html><meta charset=utf-8><title>%s</title><pre>", title);
    for (const char *s = json; *s; s++) {
        if (*s == '<')
            p += sprintf(p, "&lt;");
        else if (*s == '&')
            p += sprintf(p, "&amp;");
        else
            *p++ = *s;
    }
    strcpy(p, "</pre>\n");
    free(json);
    return page;
}

int
mcp_report_write(mcp_report *r, const char *dir)
{
    char *json = cJSON_Print(r->root);
    char *html = html_page(r);
    int rc = -1;
    if (!json || !html)
        mcp_error("out of memory writing the report");
    else if (!write_text(dir, "report.json", json) && !write_text(dir, "report.html", html))
        rc = 0;
    free(json);
    free(html);
    return rc;
}
