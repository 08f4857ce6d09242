"""Names a model may not use, because generated code would break with them.

A model's names reach generated code: parameter names become C struct members
(``params->name``) and Python locals, the model name prefixes every C
identifier and names the files (``<model>.h``, ``<model>.py``).  A name that a
header or the compiler defines as a macro (``NAN``, ``errno``, ``linux``), that
the generator itself uses (``N``, ``N_ACTIVE``), or a model name that shadows
a standard header (``math.h`` through the include path) or a Python module
(``numpy.py`` beside the generated module) produces code that does not
compile or import.  These lists are data; :func:`name_collision` is the one
check, and its answer says what the name collides with.
"""

from __future__ import annotations

import builtins
import keyword
import sys

#: C99 6.4.1 keywords.
C_KEYWORDS = frozenset(
    """auto break case char const continue default do double else enum extern
    float for goto if inline int long register restrict return short signed
    sizeof static struct switch typedef union unsigned void volatile while
    _Bool _Complex _Imaginary""".split()
)

#: Macros and identifiers of the C99 standard library (C99 7.2-7.24) that a
#: header may define as a macro, or that name a type or object the generated
#: code or a program including it uses.  Functions of <math.h>, <string.h>,
#: <stdio.h> and <stdlib.h> are listed too: the generated source includes
#: those headers, and some C libraries define functions as macros.
C_LIBRARY = frozenset(
    # 7.2 <assert.h>
    """assert NDEBUG"""
    # 7.3 <complex.h>
    """ complex imaginary I _Complex_I _Imaginary_I"""
    # 7.5 <errno.h>
    """ errno EDOM EILSEQ ERANGE"""
    # 7.6 <fenv.h>
    """ fenv_t fexcept_t FE_DIVBYZERO FE_INEXACT FE_INVALID FE_OVERFLOW FE_UNDERFLOW
    FE_ALL_EXCEPT FE_DOWNWARD FE_TONEAREST FE_TOWARDZERO FE_UPWARD FE_DFL_ENV"""
    # 7.7 <float.h>
    """ FLT_ROUNDS FLT_EVAL_METHOD FLT_RADIX DECIMAL_DIG
    FLT_MANT_DIG DBL_MANT_DIG LDBL_MANT_DIG FLT_DIG DBL_DIG LDBL_DIG
    FLT_MIN_EXP DBL_MIN_EXP LDBL_MIN_EXP FLT_MIN_10_EXP DBL_MIN_10_EXP LDBL_MIN_10_EXP
    FLT_MAX_EXP DBL_MAX_EXP LDBL_MAX_EXP FLT_MAX_10_EXP DBL_MAX_10_EXP LDBL_MAX_10_EXP
    FLT_MAX DBL_MAX LDBL_MAX FLT_EPSILON DBL_EPSILON LDBL_EPSILON FLT_MIN DBL_MIN LDBL_MIN"""
    # 7.8 <inttypes.h>, 7.18 <stdint.h> (the usual ones)
    """ int8_t int16_t int32_t int64_t uint8_t uint16_t uint32_t uint64_t intptr_t uintptr_t
    intmax_t uintmax_t INT8_MAX INT16_MAX INT32_MAX INT64_MAX INT8_MIN INT16_MIN INT32_MIN
    INT64_MIN UINT8_MAX UINT16_MAX UINT32_MAX UINT64_MAX INTMAX_MAX INTMAX_MIN UINTMAX_MAX
    SIZE_MAX PTRDIFF_MAX PTRDIFF_MIN imaxdiv_t"""
    # 7.9 <iso646.h>
    """ and and_eq bitand bitor compl not not_eq or or_eq xor xor_eq"""
    # 7.10 <limits.h>
    """ CHAR_BIT SCHAR_MIN SCHAR_MAX UCHAR_MAX CHAR_MIN CHAR_MAX MB_LEN_MAX SHRT_MIN SHRT_MAX
    USHRT_MAX INT_MIN INT_MAX UINT_MAX LONG_MIN LONG_MAX ULONG_MAX LLONG_MIN LLONG_MAX ULLONG_MAX"""
    # 7.11 <locale.h>, 7.13 <setjmp.h>, 7.14 <signal.h>, 7.15 <stdarg.h>
    """ LC_ALL LC_COLLATE LC_CTYPE LC_MONETARY LC_NUMERIC LC_TIME setjmp longjmp jmp_buf
    sig_atomic_t SIG_DFL SIG_ERR SIG_IGN SIGABRT SIGFPE SIGILL SIGINT SIGSEGV SIGTERM
    va_list va_start va_arg va_end va_copy"""
    # 7.12 <math.h>: macros
    """ HUGE_VAL HUGE_VALF HUGE_VALL INFINITY NAN FP_INFINITE FP_NAN FP_NORMAL FP_SUBNORMAL
    FP_ZERO FP_FAST_FMA FP_FAST_FMAF FP_FAST_FMAL FP_ILOGB0 FP_ILOGBNAN MATH_ERRNO
    MATH_ERREXCEPT math_errhandling float_t double_t fpclassify isfinite isinf isnan
    isnormal signbit isgreater isgreaterequal isless islessequal islessgreater isunordered"""
    # 7.12 <math.h>: functions (double versions; f and l variants follow the same names)
    """ acos asin atan atan2 cos sin tan acosh asinh atanh cosh sinh tanh exp exp2 expm1
    frexp ilogb ldexp log log10 log1p log2 logb modf scalbn scalbln cbrt fabs hypot pow
    sqrt erf erfc lgamma tgamma ceil floor nearbyint rint lrint llrint round lround llround
    trunc fmod remainder remquo copysign nan nextafter nexttoward fdim fmax fmin fma"""
    # 7.16 <stdbool.h>, 7.17 <stddef.h>
    """ bool true false __bool_true_false_are_defined NULL offsetof ptrdiff_t size_t wchar_t"""
    # 7.19 <stdio.h>
    """ FILE fpos_t EOF BUFSIZ FILENAME_MAX FOPEN_MAX L_tmpnam SEEK_CUR SEEK_END SEEK_SET
    TMP_MAX _IOFBF _IOLBF _IONBF stdin stdout stderr printf fprintf sprintf snprintf puts
    fopen fclose fread fwrite fputs fgets getc putc getchar putchar remove rename"""
    # 7.20 <stdlib.h>
    """ EXIT_FAILURE EXIT_SUCCESS RAND_MAX MB_CUR_MAX div_t ldiv_t lldiv_t malloc calloc
    realloc free abort exit atexit abs labs div rand srand qsort bsearch getenv system"""
    # 7.21 <string.h>, 7.23 <time.h>, 7.24 <wchar.h>
    """ memcpy memmove memset memcmp strlen strcpy strcmp strcat CLOCKS_PER_SEC clock_t
    time_t clock time tm WEOF WCHAR_MAX WCHAR_MIN wint_t"""
    .split()
)

#: Macros of POSIX headers and of compilers (gcc and clang in their default
#: GNU modes predefine the lowercase system names).  Identifiers beginning
#: with ``__`` or ``_`` and an uppercase letter are reserved (C99 7.1.3) and
#: refused by a rule, not listed here.
C_PLATFORM = frozenset(
    """linux unix i386 i486 i586 i686 sun sparc mips vax mc68000 m68k pdp11 hppa
    M_E M_LOG2E M_LOG10E M_LN2 M_LN10 M_PI M_PI_2 M_PI_4 M_1_PI M_2_PI M_2_SQRTPI
    M_SQRT2 M_SQRT1_2 MAXFLOAT PATH_MAX EPERM ENOENT EINTR EIO EAGAIN ENOMEM EACCES
    EEXIST EINVAL ENOSPC EPIPE""".split()
)

#: Names the generator itself defines or uses in generated C (modelgen/codegen/backends/c/*/*.j2,
#: modelgen/codegen/*.py): macros of the source file, the test driver and the
#: navigator.  tests/model/test_declaration.py fails when a template defines one not listed.
GENERATOR_C = frozenset(
    """N M N_ACTIVE N_UNIT_ROWS N_QD N_PARAMS DIM_M HUGE_SCALAR PACKED_UPPER PACKED_ANY
    STRICT_UPPER MAX_DOUBLINGS SERIES_RANGE NM MAX_IMU MAX_EPOCHS""".split()
)

#: The prefix of every header, macro and function of the fixed C runtime
#: (modelgen/codegen/backends/c/runtime, copied into each generated folder): a
#: model or quantity named with it could shadow a runtime header or macro.
RUNTIME_PREFIX = "modelgen_"

#: Names of the generated Python module (backends/python/templates/python_module.py.j2): its
#: imports, module-level names and the names its functions use, and every
#: Python builtin (a parameter becomes a local that would shadow one).  The
#: argument ``p``, the result ``out`` and temporaries ``t<k>`` are not listed:
#: the generator keeps a parameter so named as ``p[k]`` (codegen/generate.py).
GENERATOR_PYTHON = frozenset(
    """np math numpy numbers MODEL TITLE SOURCE N_STATES N_NOISES N_MEASUREMENTS TAYLOR_ORDER TAYLOR_TOLERANCE
    SERIES_RANGE PSD_TOLERANCE STATE_NAMES NOISE_NAMES MEASUREMENT_NAMES PARAMETER_NAMES
    PARAMETER_DEFAULTS SingularOperatingPoint parameter_vector system_matrix
    noise_input_matrix measurement_matrix noise_psd measurement_variance discretize predict
    update MODEL_HASH MODELGEN_VERSION matrices_evaluate update_masked reset_error_state Filter COMPILED numba
    SMOOTHER_RESET_STATES reset_inverse smooth smooth_refer smooth_step""".split()
) | frozenset(name for name in dir(builtins) if not name.startswith("_"))

#: C99 standard headers (C99 7.1.2) and common POSIX headers: a model named
#: like one generates ``<name>.h``, which the generated folder's include path
#: puts in front of the system header.
C_HEADERS = frozenset(
    """assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal
    stdarg stdbool stddef stdint stdio stdlib string tgmath time wchar wctype
    unistd fcntl pthread dirent dlfcn poll sched semaphore strings termios syslog
    alloca malloc memory endian features""".split()
)

#: Python modules a model-named ``<name>.py`` would shadow: the standard
#: library (``sys.stdlib_module_names``) and the third-party packages the
#: generated module or modelgen import.
PYTHON_MODULES = frozenset(sys.stdlib_module_names) | frozenset(
    """numpy scipy sympy casadi jinja2 yaml click pytest matplotlib modelgen""".split()
)


def name_collision(name: str, model_name: bool = False) -> str | None:
    """What ``name`` collides with in generated code, or None if it is free.

    ``model_name`` adds the checks for a model's name, which also names files
    (standard headers, Python modules).
    """
    if name in C_KEYWORDS:
        return "a C keyword"
    if keyword.iskeyword(name):
        return "a Python keyword"
    if name.startswith("__") or (len(name) > 1 and name[0] == "_" and name[1].isupper()):
        return "an identifier C reserves for the implementation (C99 7.1.3)"
    if model_name and name in C_HEADERS:
        return f"the C header <{name}.h>, which the generated {name}.h would shadow"
    if model_name and name.lower() in PYTHON_MODULES:
        return f"the Python module {name!r}, which the generated {name}.py would shadow"
    if name in C_LIBRARY:
        return "a C standard library macro or identifier"
    if name in C_PLATFORM:
        return "a POSIX or compiler-predefined macro"
    if name.lower().startswith(RUNTIME_PREFIX):
        return f"the {RUNTIME_PREFIX} prefix of the generated C runtime (modelgen/codegen/backends/c/runtime: its headers and macros)"
    if name in GENERATOR_C:
        return "a macro of the generated C"
    if name in GENERATOR_PYTHON:
        return "a name the generated Python module uses"
    return None
