/* The FMI 2.0 logger of the test hosts (native_host.c, loop_host.c): every message on stderr as
 * "[instance status category] text". Include after the FMI 2.0 headers, <stdarg.h> and <stdio.h>. */
static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s %d %s] ", name, (int)status, category);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}
