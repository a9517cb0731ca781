"""The __init__ code objects of configfile.dataclass_methods and protocol.messages, compiled
once into this module's .pyc instead of at every start-up (compile() costs ~0.9 M instructions
a function, ~4 % of a short `hil run` for the 31 it made). Each is renamed for its class with
CodeType.replace (parameter names, counts, file and line as the compiled one had). Generated:
tests/test_startup_init_templates.py holds it to `template_source()`; do not edit by hand.

store_N: dataclass_methods' `__init__(self, _0, .., _N-1): _store(self, (_0, .., ))`, the one
closure cell `_store` storing the values (a keyword-only tail: co_kwonlyargcount).
slots_N: protocol.messages' `__init__(self, _0, .., _N-1)` calling the global `_sK(self, _K)`
for each field (the slot descriptors' __set__, renamed `_set_<field>`).

The future import gives the code the flags of the callers' compile() and exec(), which inherit it.
"""
from __future__ import annotations

MAX_PARAMS = 24


def store_0(_store):
    def __init__(self):
        _store(self, ())
    return __init__


def store_1(_store):
    def __init__(self, _0):
        _store(self, (_0, ))
    return __init__


def store_2(_store):
    def __init__(self, _0, _1):
        _store(self, (_0, _1, ))
    return __init__


def store_3(_store):
    def __init__(self, _0, _1, _2):
        _store(self, (_0, _1, _2, ))
    return __init__


def store_4(_store):
    def __init__(self, _0, _1, _2, _3):
        _store(self, (_0, _1, _2, _3, ))
    return __init__


def store_5(_store):
    def __init__(self, _0, _1, _2, _3, _4):
        _store(self, (_0, _1, _2, _3, _4, ))
    return __init__


def store_6(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5):
        _store(self, (_0, _1, _2, _3, _4, _5, ))
    return __init__


def store_7(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, ))
    return __init__


def store_8(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, ))
    return __init__


def store_9(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, ))
    return __init__


def store_10(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, ))
    return __init__


def store_11(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, ))
    return __init__


def store_12(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, ))
    return __init__


def store_13(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, ))
    return __init__


def store_14(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, ))
    return __init__


def store_15(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, ))
    return __init__


def store_16(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, ))
    return __init__


def store_17(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, ))
    return __init__


def store_18(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, ))
    return __init__


def store_19(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, ))
    return __init__


def store_20(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, ))
    return __init__


def store_21(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, ))
    return __init__


def store_22(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, ))
    return __init__


def store_23(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22, ))
    return __init__


def store_24(_store):
    def __init__(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22, _23):
        _store(self, (_0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22, _23, ))
    return __init__


def slots_1(self, _0):
    _s0(self, _0)


def slots_2(self, _0, _1):
    _s0(self, _0)
    _s1(self, _1)


def slots_3(self, _0, _1, _2):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)


def slots_4(self, _0, _1, _2, _3):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)


def slots_5(self, _0, _1, _2, _3, _4):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)


def slots_6(self, _0, _1, _2, _3, _4, _5):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)


def slots_7(self, _0, _1, _2, _3, _4, _5, _6):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)


def slots_8(self, _0, _1, _2, _3, _4, _5, _6, _7):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)


def slots_9(self, _0, _1, _2, _3, _4, _5, _6, _7, _8):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)


def slots_10(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)


def slots_11(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)


def slots_12(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)


def slots_13(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)


def slots_14(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)


def slots_15(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)


def slots_16(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)


def slots_17(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)


def slots_18(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)


def slots_19(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)


def slots_20(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)
    _s19(self, _19)


def slots_21(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)
    _s19(self, _19)
    _s20(self, _20)


def slots_22(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)
    _s19(self, _19)
    _s20(self, _20)
    _s21(self, _21)


def slots_23(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)
    _s19(self, _19)
    _s20(self, _20)
    _s21(self, _21)
    _s22(self, _22)


def slots_24(self, _0, _1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, _20, _21, _22, _23):
    _s0(self, _0)
    _s1(self, _1)
    _s2(self, _2)
    _s3(self, _3)
    _s4(self, _4)
    _s5(self, _5)
    _s6(self, _6)
    _s7(self, _7)
    _s8(self, _8)
    _s9(self, _9)
    _s10(self, _10)
    _s11(self, _11)
    _s12(self, _12)
    _s13(self, _13)
    _s14(self, _14)
    _s15(self, _15)
    _s16(self, _16)
    _s17(self, _17)
    _s18(self, _18)
    _s19(self, _19)
    _s20(self, _20)
    _s21(self, _21)
    _s22(self, _22)
    _s23(self, _23)
