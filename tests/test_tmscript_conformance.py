"""The TMscript manual's own examples, with their documented results (TMscript 2.24).

Each case cites its section and page. A case is a snippet run inside ``main``; the
``Display()`` lines it prints are compared with the manual's result.
"""

from __future__ import annotations

import pytest

from tmmaster import TMScriptRuntimeError, TMScriptSyntaxError
from tmmaster.tmscript import ExecState, Execution, NullHost, display_text, evaluate, parse


def run_main(body: str, extra: str = "") -> list[str]:
    shown: list[str] = []
    program = parse(f"main\n{{\n{body}\n}}\n{extra}")
    execution = Execution(program, NullHost(on_display=shown.append, clock=lambda: 0.0))
    state = execution.run_to_end(timeout_s=5)
    if execution.error is not None:
        raise execution.error
    assert state == ExecState.ENDED
    return shown


def shown(expression: str) -> str:
    value, typ = evaluate(expression)
    return display_text(value, typ)


# (citation, expression, what TMflow shows)
EXPRESSIONS = [
    ("§2.2 p. 14 hexadecimal", "0xabcD == 0XABCD", "true"),
    ("§2.2 p. 14 binary", "0b0011 == 0B0011", "true"),
    ("§2.2 p. 14 scientific", "3.4e5 == 3.4E5", "true"),
    ("§2.2 p. 14 binary value", "0B1110000", "112"),
    ("§2.2 p. 14 hex value", "0x123abc", "1194684"),
    ("§2.2 p. 15 int overflow", "2147483647 + 1", "-2147483648"),
    ("§2.2 p. 15 int underflow", "-2147483648 - 1", "2147483647"),
    ("§2.2 p. 15 doubled quote", '"Hello TM""5"', 'Hello TM"5'),
    ("§2.2 p. 15 no control characters", '"Hello World!\\r\\n"', "Hello World!\\r\\n"),
    ("§2.2 p. 16 empty", 'empty == ""', "true"),
    ("§2.2 p. 16 True", "True", "true"),
    ("§2.2 p. 16 False", "False", "false"),
    ("§2.4 p. 19 int division", "10 / 3", "3"),
    ("§2.4 p. 19 float division", "10 / 3.0", "3.333333"),
    ("§2.4 p. 20 modulo", "4 % 3", "1"),
    ("§2.4 p. 20 shift left", "33 << 1", "66"),
    ("§2.4 p. 20 shift right", "33 >> 1", "16"),
    ("§2.4 p. 20 multiplication", "2 * 4", "8"),
    ("§2.4 p. 20 subtraction", "5 - 1", "4"),
    ("§2.4 p. 20 addition", "2 + 3", "5"),
    ("§2.4 p. 20 float division", "10.0 / 3.0", "3.333333"),
    ("§2.4 p. 19 precedence * before +", "2 + 3 * 4", "14"),
    ("§2.4 p. 19 left to right", "100 * 3 / 7 % 5", "2"),
    ("§2.4 p. 20 bitwise and", "0x0F & 42", "10"),
    ("§2.4 p. 20 bitwise xor", "0x0F ^ 42", "37"),
    ("§2.4 p. 20 bitwise or", "0x0F | 42", "47"),
    ("§2.4 p. 20 bitwise not", "~0", "-1"),
    ("§2.4 p. 20 logical not", "!true", "false"),
    ("§2.4 p. 20 less than", "41 < 42", "true"),
    ("§2.4 p. 20 less or equal", "42 <= 42", "true"),
    ("§2.4 p. 20 greater", "41 > 42", "false"),
    ("§2.4 p. 20 greater or equal", "42 >= 43", "false"),
    ("§2.4 p. 20 equal", "42 == 42", "true"),
    ("§2.4 p. 20 not equal", "41 != 42", "true"),
    ("§2.4 p. 20 logical and", "true && false", "false"),
    ("§2.4 p. 20 logical or", "true || false", "true"),
    ("§2.4 p. 20 ternary", "3 > 2 ? 3 : 2", "3"),
    ("§2.4 p. 20 && binds tighter than ||", "true || false && false", "true"),
    ("§2.4 p. 20 relational above equality", "1 < 2 == true", "true"),
    ("§2.5 p. 23 byte to int", "(int)100", "100"),
    ("§2.5 p. 23 byte to float", "(float)100", "100"),
    ("§2.5 p. 23 byte to double", "(double)100", "100"),
    ("§2.5 p. 23 0 to bool", "(bool)0", "false"),
    ("§2.5 p. 23 byte to string", "(string)100", "100"),
    ("§2.5 p. 23 int to byte", "(byte)1000", "232"),
    ("§2.5 p. 23 int to float", "(float)1000", "1000"),
    ("§2.5 p. 23 int to double", "(double)1000", "1000"),
    ("§2.5 p. 23 int to bool", "(bool)1000", "true"),
    ("§2.5 p. 23 int to string", "(string)1000", "1000"),
    ("§2.5 p. 23 float to byte", "(byte)1.23", "1"),
    ("§2.5 p. 23 float to int", "(int)1.23", "1"),
    ("§2.5 p. 23 float to double", "(double)1.23", "1.23"),
    ("§2.5 p. 23 float to bool", "(bool)1.23", "true"),
    ("§2.5 p. 23 float to string", "(string)1.23", "1.23"),
    ("§2.5 p. 23 double to float", "(float)(double)1.23", "1.23"),
    ("§2.5 p. 23 bool to string", "(string)True", "true"),
    ("§2.5 p. 23 string to byte", '(byte)"1.23"', "1"),
    ("§2.5 p. 23 string to int", '(int)"1.23"', "1"),
    ("§2.5 p. 23 string to float", '(float)"1.23"', "1.23"),
    ("§2.5 p. 23 string to double", '(double)"1.23"', "1.23"),
    ("§2.5 p. 23 string true", '(bool)"true"', "true"),
    ("§2.5 p. 23 string false", '(bool)"false"', "false"),
    ("§2.5 p. 23 non-empty string", '(bool)"1.23"', "true"),
    ("§2.5 p. 23 empty string", '(bool)""', "false"),
    ("§2.5 p. 24 string array to int[]", '(int[]){"1.23", "4.56", "0.789"}', "{1,4,0}"),
    (
        "§2.5 p. 24 string array to float[]",
        '(float[]){"1.23", "4.56", "0.789"}',
        "{1.23,4.56,0.789}",
    ),
    ("§4.1 p. 52 Byte_ToInt16 little", "Byte_ToInt16({0x90, 0x01, 0x05}, 0, 0)", "400"),
    ("§4.1 p. 52 Byte_ToInt16 big signed", "Byte_ToInt16({0x90, 0x01, 0x05}, 1, 0)", "-28671"),
    ("§4.1 p. 52 Byte_ToInt16 big unsigned", "Byte_ToInt16({0x90, 0x01, 0x05}, 1, 1)", "36865"),
    ("§4.1 p. 52 Byte_ToInt16 filled", "Byte_ToInt16({0x01}, 1, 0)", "256"),
    ("§4.1 p. 52 Byte_ToInt16 filled little", "Byte_ToInt16({0x01}, 0, 0)", "1"),
    (
        "§4.5 p. 57 Byte_ToInt16Array",
        "Byte_ToInt16Array({0x01, 0x02, 0x03, 0x04}, 1, 0)",
        "{258,772}",
    ),
    (
        "§4.5 p. 57 Byte_ToInt16Array little",
        "Byte_ToInt16Array({0x01, 0x02, 0x03, 0x04}, 0, 0)",
        "{513,1027}",
    ),
    ("§4.6 p. 59 Byte_ToInt32Array", "Byte_ToInt32Array({1, 2, 3, 4, 5}, 0)", "{67305985,5}"),
    (
        "§4.6 p. 59 Byte_ToInt32Array big",
        "Byte_ToInt32Array({1, 2, 3, 4, 5}, 1)",
        "{16909060,83886080}",
    ),
    ("§4.2 p. 54 Byte_ToInt32 filled", "Byte_ToInt32({0x01, 0x02, 0x03}, 0)", "197121"),
    ("§4.2 p. 54 Byte_ToInt32 big", "Byte_ToInt32({0x01, 0x02, 0x03}, 1)", "16909056"),
    ("§4.3 p. 55 Byte_ToFloat", "Byte_ToFloat({0x01, 0x02, 0x03, 0x4F}, 0)", "2.197947E+09"),
    ("§4.3 p. 55 Byte_ToFloat big", "Byte_ToFloat({0x01, 0x02, 0x03}, 1)", "2.387938E-38"),
    ("§4.11 p. 66 String_ToInteger", 'String_ToInteger("1234", 10)', "1234"),
    ("§4.11 p. 66 String_ToInteger hex", 'String_ToInteger("1234", 16)', "4660"),
    ("§4.11 p. 66 String_ToInteger bin", 'String_ToInteger("1100", 2)', "12"),
    ("§4.11 p. 66 prefix wins", 'String_ToInteger("0x1234", 10)', "4660"),
    ("§4.11 p. 66 negative", 'String_ToInteger("-1234", 10)', "-1234"),
    ("§4.15 p. 73 String_IndexOf", 'String_IndexOf("012314", "1")', "1"),
    ("§4.15 p. 73 String_IndexOf empty", 'String_IndexOf("012314", "")', "0"),
    ("§4.15 p. 73 String_IndexOf none", 'String_IndexOf("012314", "d")', "-1"),
    ("§4.15 p. 73 String_IndexOf from", 'String_IndexOf("012314", "1", 2)', "4"),
    ("§4.15 p. 73 String_IndexOf past", 'String_IndexOf("012314", "1", 10)', "-1"),
    ("§4.18 p. 78 String_Substring", 'String_Substring("0x12345", 2, 4)', "1234"),
    ("§4.18 p. 78 negative start", 'String_Substring("0x12345", -1, 4)', ""),
    ("§4.18 p. 78 start at end", 'String_Substring("0x12345", 7, 4)', ""),
    ("§4.18 p. 78 negative length", 'String_Substring("0x12345", 2, -1)', "12345"),
    ("§4.18 p. 78 long length", 'String_Substring("0x12345", 2, 100)', "12345"),
    ("§4.19 p. 81 String_Split", 'String_Split("0x112345", "1", 0)', "{0x,,2345}"),
    ("§4.19 p. 81 String_Split no empties", 'String_Split("0x112345", "1", 1)', "{0x,2345}"),
    ("§4.19 p. 81 String_Split empty input", 'Length(String_Split("", "1", 0))', "1"),
    ("§4.19 p. 81 String_Split empty dropped", 'Length(String_Split("", "1", 1))', "0"),
    ("§4.20 p. 82 String_Replace", 'String_Replace("0x112345", "1", "2")', "0x222345"),
    ("§4.20 p. 82 String_Replace empty", 'String_Replace("0x112345", "", "2")', "0x112345"),
    ("§4.20 p. 82 String_Replace remove", 'String_Replace("0x112345", "1", "")', "0x2345"),
    ("§4.21 p. 83 String_Trim", 'String_Trim(" 0x112345    ")', "0x112345"),
    ("§4.22 p. 85 String_ToLower", 'String_ToLower("ABc")', "abc"),
    ("§4.23 p. 86 String_ToUpper", 'String_ToUpper("abC")', "ABC"),
    ("§4.30 p. 96 Array_Reverse", "Array_Reverse({100, 200, 30})", "{30,200,100}"),
    ("§4.30 p. 96 Array_Reverse sections", "Array_Reverse({100, 200, 30}, 2)", "{200,100,30}"),
    ("§4.30 p. 96 Array_Reverse big section", "Array_Reverse({100, 200, 30}, 4)", "{30,200,100}"),
    ("§4.31 p. 98 Array_Sort", "Array_Sort({3000, 1000, 2000})", "{1000,2000,3000}"),
    (
        "§4.31 p. 98 Array_Sort strings",
        'Array_Sort({"ABC", "123", "DEF", "456"})',
        "{123,456,ABC,DEF}",
    ),
    ("§4.42 p. 133 Length byte", "Length(100)", "1"),
    ("§4.42 p. 133 Length int", "Length(400)", "4"),
    ("§4.42 p. 133 Length float", "Length(1.234)", "4"),
    ("§4.42 p. 133 Length bool", "Length(false)", "1"),
    ("§4.42 p. 133 Length string", 'Length("A""BC")', "4"),
    ("§4.34 p. 105 GetBytes byte", "GetBytes(100)", "{100}"),
    ("§4.34 p. 105 GetBytes int", "GetBytes(123456)", "{64,226,1,0}"),
    ("§2.6 p. 25 float little endian", "GetBytes((float)300)", "{0,0,150,67}"),
    ("§2.6 p. 25 double little endian", "GetBytes((double)300)", "{0,0,0,0,0,192,114,64}"),
    ("§2.6 p. 25 int little endian", "GetBytes((int)300)", "{44,1,0,0}"),
    ("§2.6 p. 25 bool", "GetBytes(true)", "{1}"),
    ("§2.6 p. 25 string UTF-8", 'GetBytes("TM Robot")', "{84,77,32,82,111,98,111,116}"),
    ("§6.1 p. 165 abs", "abs(-5)", "5"),
    ("§6.3 p. 168 sqrt", "sqrt(16.0)", "4"),
    ("§6.4 p. 169 ceil", "ceil(1.2)", "2"),
    ("§6.5 p. 170 floor", "floor(-1.2)", "-2"),
    ("§6.16 p. 183 sin in degrees", "sin(90.0)", "1"),
    ("§6.17 p. 184 cos in degrees", "cos(0.0)", "1"),
    ("§6.22 p. 189 atan2", "atan2(1.0, 1.0)", "45"),
    ("§6.14 p. 181 d2r of a float", "d2r(180.0)", "3.141593"),
    ("§6.14 p. 181 d2r of a double", "d2r((double)180.0)", "3.14159265358979"),
]


@pytest.mark.parametrize(
    ("cite", "expression", "expected"), EXPRESSIONS, ids=[c[0] for c in EXPRESSIONS]
)
def test_expressions(cite: str, expression: str, expected: str) -> None:
    assert shown(expression) == expected


# (citation, statements in main, Display lines)
PROGRAMS = [
    ("§2.2 p. 15 byte keeps 8 bits", "byte bv = 0 - 100\nDisplay(bv)", ["156"]),
    ("§2.2 p. 15 byte wraps up", "byte bv = 255 + 1\nDisplay(bv)", ["0"]),
    ("§2.2 p. 15 byte wraps down", "byte bv = 0 - 1\nDisplay(bv)", ["255"]),
    (
        "§2.2 p. 14 strings join",
        'string s1 = "DEF"\nstring s2 = "123"\nstring s = s1 + " and " + s2\nDisplay(s)',
        ["DEF and 123"],
    ),
    (
        "§2.2 p. 15 standard syntax",
        'string s = "TM5"\nDisplay("Hi, " + s + " Robot")',
        ["Hi, TM5 Robot"],
    ),
    ("§2.2 p. 15 quoted variable is text", 's = "TM5"\n', None),
    (
        "§2.3 p. 18 String_Split resizes",
        "string[] ss = {empty, empty, empty}\n"
        'ss = String_Split("A_B_C_D_F_G_H", "_")\nDisplay(Length(ss))\n'
        'ss = String_Split("A,B", ",")\nDisplay(Length(ss))',
        ["7", "2"],
    ),
    (
        "§2.4 p. 19 int/int then float",
        "int var_a = 10\nint var_b = 3\nfloat var_c = var_a / var_b\nDisplay(var_c)",
        ["3"],
    ),
    (
        "§2.4 p. 19 int/float",
        "int var_a = 10\nfloat var_b = 3\n"
        "float var_c = var_a / var_b\nDisplay(var_c)\nvar_c = var_a / 3\nDisplay(var_c)\n"
        "var_c = var_a / 3.0\nDisplay(var_c)",
        ["3.333333", "3", "3.333333"],
    ),
    (
        "§2.4 p. 19 right-to-left assignment",
        "int A = 10\nint B = 1\nA -= B += 10\nDisplay(A)\nDisplay(B)",
        ["-1", "11"],
    ),
    (
        "§2.4 p. 20 compound assignments",
        "int a = 1\na += 3\na *= 5\na /= 2\na %= 3\na <<= 2\na |= 1\nDisplay(a)",
        ["5"],
    ),
    (
        "§2.4 p. 19 postfix and prefix",
        'int i = 1\nint j = i++\nint k = ++i\nDisplay(j + " " + k + " " + i)',
        ["1 3 3"],
    ),
    ("§2.7 p. 27 float to int truncates", "int i = 0\nfloat f = 1.234\ni = f\nDisplay(i)", ["1"]),
    ("§2.7 p. 27 narrowing to byte", "byte bv = 100\nint i = 1000\nbv = i\nDisplay(bv)", ["232"]),
    (
        "§2.7 p. 27 string to int",
        'int i = "1234"\nint j = "0x89AB"\nint k = "0b1010"\nDisplay(i + "," + j + "," + k)',
        ["1234,35243,10"],
    ),
    ("§2.7 p. 27 number to string", "string s1 = 123\nDisplay(s1)", ["123"]),
    ("§3.2 p. 29 main displays", 'Display("Hello Techman Robot")', ["Hello Techman Robot"]),
    (
        "§3.5 p. 32 customized functions",
        'string Add_Result = "Add:" + Add(5.9, 3.6)\n'
        'string Sub_Result = "Sub:" + Sub(5.9, 3.6)\nDisplay(Add_Result)\nDisplay(Sub_Result)',
        ["Add:9.5", "Sub:2.3"],
    ),
    ("§3.6 p. 33 comments", "int a = 0\n// a = a + 1\n/*\na = a + 1\n*/\nDisplay(a)", ["0"]),
    ("§3.8 p. 37 multi-line input", 'string s = "a" + \\\n "b"\nDisplay(s)', ["ab"]),
    (
        "§3.9.1 p. 38 if else if",
        'int Score = 65\nif (Score == 100)\n{\nDisplay("Full Score")\n}\n'
        'else if (Score >= 60)\n{\nDisplay("Excellent")\n}\nelse\n{\nDisplay("Failed")\n}',
        ["Excellent"],
    ),
    (
        "§3.9.1 p. 39 string conditions",
        'if ("True") Display("yes")\nif ("yes") Display("no")',
        ["yes"],
    ),
    (
        "§3.9.2 p. 40 switch on strings",
        'string di_st = "01"\nswitch (di_st)\n{\ncase "00"\n'
        'Display("a")\nbreak\ncase "01"\nDisplay("b")\nbreak\ndefault\nDisplay("c")\nbreak\n}',
        ["b"],
    ),
    (
        "§3.9.2 p. 40 switch with comparisons",
        "int Score = 65\nswitch (Score)\n{\ncase >= 100\n"
        'Display("Full Score")\nbreak\ncase >= 100-40\nDisplay("Excellent")\nbreak\ndefault\n'
        'Display("Failed")\nbreak\n}',
        ["Excellent"],
    ),
    ("§3.10.1 p. 42 for sum", "Display(sum(10))", ["45"]),
    (
        "§3.10.1 p. 43 optional sections",
        "int i = 0\nfor (i = 3; i < 4; )\ni++\nDisplay(i)\n"
        "for ( ; i < 5; i++)\n{\n}\nDisplay(i)\nfor ( ; ; )\n{\nbreak\n}",
        ["4", "5"],
    ),
    (
        "§3.10.2 p. 43 while",
        "int sum = 0\nint N = 0\nwhile (sum != 500500)\n{\nN += 1\nsum += N\n}\nDisplay(N)",
        ["1000"],
    ),
    (
        "§3.10.3 p. 44 do while runs once",
        'int result = 0\ndo\n{\nDisplay("Hello TM Robot")\n} while(result > 5)',
        ["Hello TM Robot"],
    ),
    (
        "§3.10.3 p. 44 while runs never",
        'int result = 0\nwhile(result > 5)\n{\nDisplay("Hello TM Robot")\n}',
        [],
    ),
    ("§3.11.1 p. 45 break", "Display(sum_break(100))", ["55"]),
    (
        "§3.11.1 p. 45 inner break",
        'string result = ""\nfor (int i = 1; i <= 2; i++)\n{\n'
        "for (int j = 1; j <= 9; j++)\n{\nresult += j\nif (j > 4) break\n}\n"
        'result += ";"\n}\nDisplay(result)',
        ["12345;12345;"],
    ),
    (
        "§3.11.2 p. 46 continue",
        'string result = ""\nfor (int i = 0; i < 10; i++)\n{\n'
        'if (i % 2 == 0)\n{\ncontinue\n}\nresult += i + ", "\n}\nDisplay("Odd value: " + result)',
        ["Odd value: 1, 3, 5, 7, 9, "],
    ),
    ("§3.11.3 p. 46 return", "int num = sum_return(10)\nDisplay(num)", ["3"]),
    ("§3.7 p. 34 project variable", 'Test1()\nDisplay("B Value: " + b)', ["B Value: 20"]),
    (
        "§3.7 p. 36 out of scope word is a string",
        'int a = 10\nif (a > 5)\n{\nint b2 = 20\n}\nDisplay("B Value: " + b2)',
        ["B Value: b2"],
    ),
    (
        "§3.10.1 p. 43 multiplication table",
        'string result = ""\nfor (int i = 1; i <= 2; i++)\n'
        '{\nfor (int j = 1; j <= 2; j++)\n{\nresult += j + "X" + i + "=" + i * j + " "\n}\n}\n'
        "Display(result)",
        ["1X1=1 2X1=2 1X2=2 2X2=4 "],
    ),
    (
        "§4.24 p. 87 Array_Append",
        "int[] n1 = {100, 200}\nn1 = Array_Append(n1, 300)\nDisplay(n1)",
        ["{100,200,300}"],
    ),
    (
        "§4.24 p. 87 Array_Append strings",
        'string[] n2 = {"ABC", "123", "XYZ"}\n'
        'string[] n4 = Array_Append(n2, "Hello World")\nDisplay(n4)',
        ["{ABC,123,XYZ,Hello World}"],
    ),
    (
        "§4.26 p. 89 Array_Remove",
        "int[] n1 = {100, 200, 30, 40, 50, 60}\nint[] n6 = Array_Remove(n1, 1, 2)\nDisplay(n6)",
        ["{100,40,50,60}"],
    ),
    (
        "§4.26 p. 89 Array_Remove to the end",
        "int[] n1 = {100, 200, 30, 40, 50, 60}\nDisplay(Array_Remove(n1, 1, 100))",
        ["{100}"],
    ),
    (
        "§4.26 p. 89 Array_Remove last",
        "int[] n1 = {100,200,30,40,50,60,70}\nDisplay(Array_Remove(n1, Length(n1)-1))",
        ["{100,200,30,40,50,60}"],
    ),
    ("§2.3 p. 18 indexing", "int[] A = {0,1,2,3,4,5,6,7}\nA[4] = 2\nDisplay(A[4] + A[7])", ["9"]),
]

FUNCTIONS = """
define
{
  int b = 0
}
float Add(float augend, float addend)
{
  float result = augend + addend
  return result
}
float Sub(float minuend, float subtrahend)
{
  float result = minuend - subtrahend
  return result
}
int sum(int k)
{
  int result = 0
  for (int i = 0; i < k; i++)
  {
    result += i
  }
  return result
}
int sum_break(int k)
{
  int result = 0
  for (int i = 0; i < k; i++)
  {
    if (i > 10)
    {
      break
    }
    result += i
  }
  return result
}
int sum_return(int k)
{
  int result = 0
  for (int i = 0; i < k; i++)
  {
    if (i == 3) return result
    result += i
  }
  return result
}
void Test1()
{
  b = 20
}
"""


@pytest.mark.parametrize(
    ("cite", "body", "expected"),
    [p for p in PROGRAMS if p[2] is not None],
    ids=[p[0] for p in PROGRAMS if p[2] is not None],
)
def test_programs(cite: str, body: str, expected: list[str]) -> None:
    assert run_main(body, FUNCTIONS) == expected


# (citation, expression or statements, the manual's error)
ERRORS = [
    ("§2.5 p. 23 bool to byte", "(byte)True"),
    ("§2.5 p. 23 bool to int", "(int)False"),
    ("§2.5 p. 23 bool to float", "(float)true"),
    ("§2.5 p. 23 bool to double", "(double)false"),
    ("§2.5 p. 23 XYZ to byte", '(byte)"XYZ"'),
    ("§2.5 p. 23 A1 to float", '(float)"A1"'),
    ("§2.5 p. 24 XYZ to int", '(int)"XYZ"'),
    ("§2.5 p. 24 double out of float", '(float)"1.79769e+308"'),
    ("§3.4 p. 31 divide by zero", '100 / (byte)"0.1"'),
]


@pytest.mark.parametrize(("cite", "expression"), ERRORS, ids=[e[0] for e in ERRORS])
def test_documented_conversion_errors(cite: str, expression: str) -> None:
    with pytest.raises(TMScriptRuntimeError):
        evaluate(expression)


def test_string_to_int_fails_at_run_time() -> None:
    # TMscript 2.24 §2.7, p. 27: compiles with a warning, stops by error when executing.
    with pytest.raises(TMScriptRuntimeError, match="XYZ"):
        run_main('string s2 = "XYZ"\nint x = s2')
    with pytest.raises(TMScriptRuntimeError):
        run_main('string s2 = ""\nint x = s2')


def test_bare_word_is_a_string_with_a_warning() -> None:
    # TMscript 2.24 §2.7, p. 27: string s = Hello
    program = parse("main\n{\nstring s = Hello\nDisplay(s)\n}\n")
    assert [w.line for w in program.warnings] == [3]
    assert run_main("string s = Hello\nDisplay(s)") == ["Hello"]


def test_duplicate_variables_are_refused() -> None:
    # TMscript 2.24 §3.7, p. 35: duplicated with define, duplicated in the function.
    with pytest.raises(TMScriptSyntaxError, match="twice"):
        parse("define\n{\nint b = 0\n}\nvoid f(int s)\n{\nint b = 1\n}\n")
    with pytest.raises(TMScriptSyntaxError, match="twice"):
        parse("void f(int s)\n{\nint a = 0\nfloat a = 0\n}\n")
    # Independent functions may use the same name (p. 35).
    parse("void T1()\n{\nint a = 0\n}\nvoid T2()\n{\nint a = 2\n}\n")


def test_display_syntaxes() -> None:
    # TMscript 2.24 §5.6, p. 160-161: four, two or one strings.
    lines = run_main(
        'Display("Yellow", "Green", "Gripper Initial Finish", "Force = 30N")\n'
        'Display("Title", "Text")\nDisplay("Text")'
    )
    assert lines == ["Gripper Initial Finish: Force = 30N", "Title: Text", "Text"]
