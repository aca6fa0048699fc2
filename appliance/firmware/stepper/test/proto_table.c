/* proto_table.c -- the protocol table as the C side compiled it, one item a line:
 *
 *   CONSTANT <name> <value>
 *   REALTIME <name> <byte>
 *   VERB <name> <arguments> <error proto_parse gives a sealed line with that many arguments>
 *
 * tests/test_fw_host.py compares the listing with appliance/hw/protocol.py, so a
 * constant or verb that one side spells by hand and the other does not fails there.
 * The verbs are read from the parser's own table and run through the parser. */
#include <stdio.h>
#include <string.h>
#include "crc.h"
#include "protocol.h"

static int parse_error(const char *verb, uint8_t args)
{
  char line[LINE_MAX + 1];
  int n = snprintf(line, sizeof line, "1 %s", verb);
  for (uint8_t i = 0; i < args; i++) n += snprintf(line + n, sizeof line - (size_t)n, " 1");
  n += snprintf(line + n, sizeof line - (size_t)n, "*%04X", crc16(line, (size_t)n));
  command_t c;
  return proto_parse(line, (uint8_t)n, &c);
}

int main(void)
{
  printf("CONSTANT PROTO_VERSION %d\n", PROTO_VERSION);
  printf("CONSTANT LINE_MAX %d\n", LINE_MAX);
  printf("REALTIME RT_STATUS %d\n", RT_STATUS);
  printf("REALTIME RT_ESTOP %d\n", RT_ESTOP);
  for (uint8_t v = 0; v < V_COUNT; v++)
    printf("VERB %s %u %d\n", proto_verb_names[v], proto_verb_args[v],
           parse_error(proto_verb_names[v], proto_verb_args[v]));
  return 0;
}
