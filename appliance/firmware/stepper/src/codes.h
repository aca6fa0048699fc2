/* codes.h -- enums generated from ../codes.def, the one table both sides read. */
#ifndef CODES_H
#define CODES_H

#define CONSTANT(name, value, text) name = value,
enum proto_constant {
#include "../codes.def"
};
#undef CONSTANT

#define REALTIME(name, byte, text) name = byte,
enum realtime_byte {
#include "../codes.def"
};
#undef REALTIME

#define VERB(name, args, text) V_##name,
enum verb {
#include "../codes.def"
  V_COUNT
};
#undef VERB

#define CODE_ERR(num, name, text) ERR_##name = num,
#define CODE_STATE(num, name, text)
#define CODE_FLAG(num, name, text)
#define CODE_ALARM(num, name, text)
#define CODE_RESET(num, name, text)
#define CODE(kind, num, name, text) CODE_##kind(num, name, text)
enum err_code {
  ERR_none = 0,
#include "../codes.def"
};
#undef CODE_ERR
#define CODE_ERR(num, name, text)
#undef CODE_STATE
#define CODE_STATE(num, name, text) STATE_##name = num,
enum state_code {
#include "../codes.def"
};
#undef CODE_STATE
#define CODE_STATE(num, name, text)
#undef CODE_FLAG
#define CODE_FLAG(num, name, text) FLAG_##name = (1u << num),
enum flag_bits {
#include "../codes.def"
};
#undef CODE_FLAG
#define CODE_FLAG(num, name, text)
#undef CODE_ALARM
#define CODE_ALARM(num, name, text) ALARM_##name = num,
enum alarm_code {
#include "../codes.def"
};
#undef CODE_ALARM
#define CODE_ALARM(num, name, text)
#undef CODE_RESET
#define CODE_RESET(num, name, text) RESET_##name = num,
enum reset_code {
#include "../codes.def"
};
#undef CODE_RESET
#undef CODE
#undef CODE_ERR
#undef CODE_STATE
#undef CODE_FLAG
#undef CODE_ALARM

#define SETTING(num, name, dflt, lo, hi, text) SET_##name = num,
enum setting_id {
#include "../codes.def"
  SETTING_COUNT
};
#undef SETTING

#endif
