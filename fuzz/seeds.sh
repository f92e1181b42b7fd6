#!/usr/bin/env bash
# Rebuilds the committed seed corpus (fuzz/corpus/<target>/seed-*) from fixtures/.
# Regression seeds (seed-regression-*) are kept. Run from anywhere.
set -euo pipefail
cd "$(dirname "$0")"
F=../fixtures
C=corpus
for t in blackboard sfc irl template value splice compile cond; do
  mkdir -p "$C/$t"
  find "$C/$t" -name 'seed-*' ! -name 'seed-regression-*' -delete
done

# Project files of the ok fixtures: case name, blackboard, SFC, IRL.
ok=(
  "reference-sample|Blackboard.aml|sfc.xml|kr15-2.irl"
  "caex3-english|Cell.aml|PickPlace.sfc.xml|kr16.irl"
  "lf-output|Glue.aml|glue.xml|kr3.irl"
  "mappings-overloads|WeldCell.aml|weld_plan.xml|weld.irl"
  "no-writeback-target|Deburring.aml|deburr.xml|kr30.irl"
  "subfolders|Palletizing Cell.aml|Process Plans/Layer 1.xml|Robot Library/KR6/kr6 r900.irl"
  "typed-values|Setup.aml|setup.xml|kr10.irl"
  "umlauts|Zelle_Übergabe.aml|Ablauf.xml|greifer.irl"
  "writeback-insert-value|Drilling.aml|drill.xml|kr60.irl"
)
# The flow fixtures: the shared base's blackboard and IRL file, each case's SFC.
for d in "$F"/ok/flow-*/; do
  case=$(basename "$d")
  cp "$d/sfc.xml" "$C/sfc/seed-ok-$case"
  { cat "$F/base/flow/Blackboard.aml"; printf '\0'; cat "$d/sfc.xml"; printf '\0'; cat "$F/base/flow/kr15-2.irl"; } \
    >"$C/compile/seed-ok-$case"
done
for line in "${ok[@]}"; do
  IFS='|' read -r case bb sfc irl <<<"$line"
  d="$F/ok/$case"
  cp "$d/$bb" "$C/blackboard/seed-ok-$case"
  cp "$d/$sfc" "$C/sfc/seed-ok-$case"
  cp "$d/$irl" "$C/irl/seed-ok-$case"
  { cat "$d/$bb"; printf '\0'; cat "$d/$sfc"; printf '\0'; cat "$d/$irl"; } >"$C/compile/seed-ok-$case"
done
cp "$F/ok/subfolders/Robot Library/vacuum.irl" "$C/irl/seed-ok-subfolders-vacuum"

# Error fixtures (all named Blackboard.aml, sfc.xml, kr15-2.irl).
for e in e101_blackboard_not_utf8 e102_blackboard e102_blackboard_dtd e201_two_unnamed_hierarchies \
         e204_dot_in_attribute_name e205_index_not_a_number e206_two_data_interfaces \
         e207_order_not_integer e208_duplicate_skill; do
  cp "$F/err/$e/Blackboard.aml" "$C/blackboard/seed-err-$e"
done
for e in e101_sfc_not_utf8 e102_sfc e302_duplicate_local_id e306_n_to_m e309_cycle \
         e310_divergence_not_converged e310_selection_branch_without_transition e315_unclosed_list \
         e503_quote e316_condition_syntax e317_jump_target_names_several_steps; do
  cp "$F/err/$e/sfc.xml" "$C/sfc/seed-err-$e"
done
for e in e102_irl e401_empty_definition e402_unknown_command e602_irl_call \
         e602_irl_definition_char_ref; do
  cp "$F/err/$e/kr15-2.irl" "$C/irl/seed-err-$e"
done
for e in e315_unclosed_list e403_no_overload_fits e502_integer e504_index_out_of_range \
         e601_too_long e602_value e309_cycle; do
  d="$F/err/$e"
  { cat "$d/Blackboard.aml"; printf '\0'; cat "$d/sfc.xml"; printf '\0'; cat "$d/kr15-2.irl"; } \
    >"$C/compile/seed-err-$e"
done

# Templates: `PARAMS\0TEXT`, or a text alone (parameters from its first bracket group).
n=0
tpl() { n=$((n + 1)); printf '%b' "$1" >"$C/template/seed-$n"; }
tpl 'X,Y,Z,A,B,C\0PTP {X, Y, Z, A, B, C}'
tpl 'X,Y,Z,A,B,C\0LIN {E6POS: X 1, Y Y, Z, A, B, C} C_DIS ; comment X'
tpl 'VALUE\0SetVelCP (VALUE)\n$VEL.CP = VALUE\nVALUE.X = #VALUE'
tpl 'P,Q\0x = "P and Q" ; P\n{POS {P, Q}, E1 P}\nWAIT SEC P'
tpl 'SPEED,Tool\0$TOOL = TOOL_DATA[tool]\n$OV_PRO = speed\nBAS(#VEL_PTP, SPEED)'
tpl 'Wert,Größe\0Greifer(WERT, größe, 1E3, '"'"'H1F'"'"')'
tpl 'PTP {X, Y, Z, A, B, C}'
tpl 'Grip(Force, "open", Width) ; comment'
tpl '  LIN_REL {X, Y}\r\n\tWAIT FOR $IN[IO]'

# Values: one selector byte, then the value text.
n=0
val() { n=$((n + 1)); printf '%b' "$1" >"$C/value/seed-$n"; }
val '\x00(100, 200, 300, 0, 90, 0)'
val '\x45((400, -150, 300, 0, 135, 0), (400, 150, 300, 0, 135, 0))'
val '\x86(1, (2, 3), ())'
val '\x01("a,b", c)'
val '\x02  0.5  '
val '\x03#PTP_PARAMS'
val '\x04"cell 7"'
val '\x05(1, 2'
val '\x06(1,,2)'
val '\x07(1) x'
val '\x08((((((a))))))'
val '\x09( "x)" , y )'

# Splice: selector byte, value, NUL, document (selector bit 0: the document part is the
# Attribute element, wrapped into a blackboard skeleton).
n=0
spl() { n=$((n + 1)); printf '%b' "$1" >"$C/splice/seed-$n"; }
spl '\x01output.src\0<Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>none</Value></Attribute>'
spl '\x01p.src\0<Attribute Name="refURI"/>'
spl '\x01p.src\0<Attribute Name="refURI" >\n  <Description>x</Description>\n  <RefSemantic CorrespondingAttributePath="a"/>\n</Attribute>'
spl '\x01a&b <c>\0<x:Attribute Name="refURI"><x:Value a='"'"'/>'"'"' /><Attribute Name="n"><Value>y</Value></Attribute></x:Attribute>'
spl '\x01 v \0<Attribute Name="refURI" D="a>/"><!--c--><?p?><Value><![CDATA[ v ]]>&amp;<b>t</b></Value></Attribute>'
spl '\x03ä\r\n\0<Attribute Name="refURI"><Value>\r\n</Value><Constraint Name="c"/></Attribute>'
printf '\x00output.src\0' | cat - "$F/ok/reference-sample/Blackboard.aml" >"$C/splice/seed-ok-reference-sample"
printf '\x2eoutput.src\0' | cat - "$F/ok/writeback-insert-value/Drilling.aml" >"$C/splice/seed-ok-writeback-insert-value"

# Conditions: the flow fixtures' conditions, and hand-written ones (operators, precedence,
# comments, errors).
n=0
cnd() { n=$((n + 1)); printf '%b' "$1" >"$C/cond/seed-$n"; }
cnd 'TRUE'
cnd 'Part_OK'
cnd 'NOT Magazine_Empty AND (Release OR Door_Closed)'
cnd 'Gripper_Closed = TRUE'
cnd 'Variant = 2 OR Variant >= 12'
cnd 'a XOR b & NOT (c <> d) OR -n < -3'
cnd 'x >= 1.5 (* a comment *) AND y <= 2'
cnd 'n = 3 AND m < 2 = FALSE'
cnd '((((a))))'
cnd 'a AND'
cnd 'Robot.Ready'
cnd '%IX0.1'
cnd 'a := 1'
cnd '(* open'
cnd 'Gr\xc3\xb6\xc3\x9fe'
cnd '3a OR 16#FF'

du -sh "$C"
for t in blackboard sfc irl template value splice compile cond; do
  echo "$t: $(find "$C/$t" -name 'seed-*' | wc -l) seeds"
done

