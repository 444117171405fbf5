/* test_plugins.c: common/core/paths.c's plug-in loading as the command line asks for
 * it (mcp__plugins_one_blas_thread): OpenCV's plug-in loads LAPACK and with it the
 * system's BLAS; where that is OpenBLAS, it must have started no thread pool (one
 * thread), and the environment must be as it was, so that the programs mcpost runs see
 * the user's. The whole test is one process, so that OpenBLAS is loaded here for the
 * first time. */
#include "testing.h"

#include "../../common/core/internal.h"
#include <mcpost/filter.h>

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

static void
test_plugin_loads_without_blas_threads(void **state)
{
    (void)state;
    if (getenv("OPENBLAS_NUM_THREADS")) {
        skip(); /* the user's value wins; nothing to check */
        return;
    }
    assert_null(dlopen("libopenblas.so.0", RTLD_LAZY | RTLD_NOLOAD));
    mcp__plugins_one_blas_thread();
    /* a separable filter runs in the OpenCV plug-in, which loads it */
    mcp_image *img = NULL, *out = NULL;
    assert_int_equal(mcp_image_new(64, 32, 3, NULL, &img), 0);
    const float k[3] = {0.25f, 0.5f, 0.25f};
    assert_int_equal(mcp_filter_separable(img, k, 3, k, 3, &out), 0);
    mcp_image_free(img);
    mcp_image_free(out);
    assert_null(getenv("OPENBLAS_NUM_THREADS"));
    void *blas = dlopen("libopenblas.so.0", RTLD_LAZY | RTLD_NOLOAD);
    if (!blas) {
        printf("the plug-in's BLAS is not OpenBLAS here; nothing more to check\n");
        return;
    }
    int (*threads)(void) = (int (*)(void))dlsym(blas, "openblas_get_num_threads");
    assert_non_null(threads);
    assert_int_equal(threads(), 1);
    dlclose(blas);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_plugin_loads_without_blas_threads),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
